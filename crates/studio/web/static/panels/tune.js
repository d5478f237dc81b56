// Tune: a wCK servo's gains, speed, overload and boundaries; a WHJ joint's registers; and
// the step response of a wCK servo under several gain sets (`wck.tune`), drawn over each
// other with the step's target.

import { el, h, field, numberInput, select, fmt, devicePicker, reportProblem, describeError, newId, writes } from "../ui.js";
import { createFlow, flowButtons, labelled, boundedNumber, reportTable } from "./flow.js";

/** The wCK parameters: their fields, ranges and whether a runtime write exists. */
const WCK_PARAMS = [
  {
    param: "gains",
    title: "Position gains",
    runtime: true,
    fields: [
      ["p", "P gain", "p_gain", 1, 254],
      ["d", "D gain", "d_gain", 0, 254],
    ],
  },
  { param: "i-gain", title: "I gain", runtime: true, fields: [["i", "I gain", "i_gain", 0, 254]] },
  {
    param: "speed",
    title: "Speed and acceleration",
    runtime: true,
    fields: [
      ["speed", "Speed", "speed", 0, 30],
      ["accel", "Acceleration", "accel", 20, 100],
    ],
  },
  {
    param: "overload",
    title: "Overload",
    runtime: false,
    fields: [["milliamps", "Overload (mA)", "milliamps", 400, 1800, 1]],
  },
  {
    param: "bounds",
    title: "Boundaries",
    runtime: false,
    fields: [
      ["lower", "Lower bound (steps)", "lower", 0, 254],
      ["upper", "Upper bound (steps)", "upper", 0, 254],
    ],
  },
];

export default {
  id: "tune",
  title: "Tune",
  mount(root, studio) {
    root.append(
      el("h2", {}, "Tune"),
      el("p", { className: "lead" }, "Read and write a device's settings. EEPROM and flash writes ask first; runtime writes last until the device is powered off."),
    );
    const cols = el("div", { className: "columns tune-cols" });
    root.append(cols);
    if (studio.buses("wck").length) cols.append(wckSection(studio));
    if (studio.buses("whj").length) cols.append(whjSection(studio));
    if (studio.buses("wck").length) root.append(stepSection(studio));
  },
};

/** Colours of the gain sets' traces (the target is drawn in black, dashed). */
const TRACE_COLOURS = ["#1f6feb", "#d1242f", "#1a7f37", "#9a6700", "#8250df", "#bf3989", "#0a7b83", "#57606a"];

/**
 * The step response: a servo, its gain sets, the step; `wck.tune` through the flow (its
 * dry run, arming: it moves the servo; an EEPROM keep asks first); the report's figures as
 * a table and every set's trace drawn over the others with the target step.
 */
function stepSection(studio) {
  const picker = devicePicker(studio, { families: ["wck"], label: "Servo" });
  picker.select.setAttribute("aria-label", "Step response servo");
  const gains = el("input", { type: "text", value: "20,30; 60,10", size: 24, spellcheck: false });
  const amplitude = numberInput({ value: 20, min: 2, max: 60 });
  const hold = numberInput({ value: 400, min: 100, max: 5000, step: 50 });
  const torque = numberInput({ value: 0, min: 0, max: 4 });
  const keep = select([["none", "nothing (back to the EEPROM gains)"], ["runtime", "the best set, runtime"], ["eeprom", "the best set, EEPROM"]], "none");
  const flow = createFlow(studio, { name: "Step response", render: drawTune });
  const build = () => {
    const d = picker.get();
    if (!d) throw new Error("pick a servo");
    const sets = gains.value.split(";").map((t) => t.trim()).filter(Boolean).map((t) => {
      const m = /^(\d+)\s*[, ]\s*(\d+)$/.exec(t);
      if (!m) throw new Error(`Gain sets: "${t}" is not P,D (sets separated by ";", e.g. 20,30; 60,10)`);
      return [Number(m[1]), Number(m[2])];
    });
    if (!sets.length) throw new Error("Gain sets: give at least one P,D");
    return {
      op: "wck.tune", bus: d.bus, id: d.id, gains: sets,
      amplitude: boundedNumber(amplitude, "Step (steps)", 2, 60),
      hold_ms: boundedNumber(hold, "Hold (ms)", 100, 5000),
      torque: boundedNumber(torque, "Torque", 0, 4),
      keep: keep.value,
    };
  };
  return el("section", { className: "card", "aria-label": "Step response" }, [
    el("h3", {}, "Step response"),
    el("p", { className: "hint" }, "The same position step with each gain set (runtime gains), recorded and drawn over each other with the step's target; the servo starts at rest and returns there. It moves the servo: arm first."),
    el("div", { className: "row" }, [picker.element, labelled("Gain sets (P,D; P,D)", gains), labelled("Step (steps)", amplitude),
      labelled("Hold (ms)", hold), labelled("Torque", torque), labelled("Keep", keep)]),
    flowButtons(studio, flow, { label: "Run the steps", name: "Run the step responses", build }),
    flow.element,
  ]);
}

/** `wck.tune`'s report: its figures, and its traces against the target step. */
function drawTune(rep, req) {
  if (rep.failed) return h("p", { class: "fail" }, `${rep.failed}: ${rep.error ?? "failed"}`);
  const s = rep.summary ?? {};
  const rows = rep.results ?? [];
  const best = s.best == null ? (s.tied?.length ? `a tie between sets ${s.tied.map((i) => i + 1).join(", ")}` : "none") : `set ${s.best + 1} (P ${rows[s.best]?.p}, D ${rows[s.best]?.d})`;
  return [
    h("p", { "data-field": "best" }, `Step from ${s.start} to ${s.target} (position steps). Best: ${best}; kept: ${s.kept}.`),
    stepChart(s, req),
    reportTable("Step responses", [["Set", (r) => rows.indexOf(r) + 1], ["P", "p"], ["D", "d"], ["Rise (ms)", "rise_ms"],
      ["Overshoot (%)", "overshoot_pct"], ["Settling (ms)", "settling_ms"], ["Steady-state error", "steady_state_error"]], rows),
  ];
}

/** An SVG of every response's trace (ms, position) and the target step. */
function stepChart(s, req) {
  const W = 720;
  const H = 300;
  const L = 48;
  const B = 34;
  const T = 26;
  const R = 12;
  const responses = s.responses ?? [];
  const all = responses.flatMap((r) => r.trace ?? []);
  const tMax = Math.max(req.hold_ms ?? 0, ...all.map((p) => p[0]), 1);
  const vals = [s.start, s.target, ...all.map((p) => p[1])];
  let lo = Math.min(...vals);
  let hi = Math.max(...vals);
  const pad = Math.max(1, (hi - lo) * 0.08);
  lo -= pad;
  hi += pad;
  const tPre = tMax * 0.05;
  const x = (t) => L + ((t + tPre) / (tMax + tPre)) * (W - L - R);
  const y = (v) => T + (1 - (v - lo) / (hi - lo)) * (H - T - B);
  const ns = "http://www.w3.org/2000/svg";
  const svg = document.createElementNS(ns, "svg");
  const add = (tag, attrs, text) => {
    const e = document.createElementNS(ns, tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
    if (text !== undefined) e.textContent = text;
    svg.append(e);
    return e;
  };
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  svg.setAttribute("class", "step-chart");
  svg.setAttribute("role", "img");
  svg.setAttribute("aria-label", `Step responses: ${responses.length} gain sets against the target, position steps over ms`);
  add("line", { x1: L, y1: H - B, x2: W - R, y2: H - B, stroke: "#999" });
  add("line", { x1: L, y1: T, x2: L, y2: H - B, stroke: "#999" });
  for (let i = 0; i <= 4; i++) {
    const v = lo + ((hi - lo) * i) / 4;
    add("text", { x: L - 6, y: y(v) + 4, "text-anchor": "end" }, v.toFixed(0));
    add("line", { x1: L, y1: y(v), x2: W - R, y2: y(v), stroke: "#eee" });
    const t = (tMax * i) / 4;
    add("text", { x: x(t), y: H - B + 15, "text-anchor": "middle" }, t.toFixed(0));
  }
  add("text", { x: (L + W - R) / 2, y: H - 4, "text-anchor": "middle" }, "ms since the step");
  add("text", { x: 6, y: 14, "text-anchor": "start" }, "position (steps)");
  // The target: the start before the step, the target from it on.
  add("polyline", {
    points: [[-tPre, s.start], [0, s.start], [0, s.target], [tMax, s.target]].map(([t, v]) => `${x(t).toFixed(1)},${y(v).toFixed(1)}`).join(" "),
    fill: "none", stroke: "#111", "stroke-width": 1.5, "stroke-dasharray": "5 4", "data-series": "target",
  });
  responses.forEach((r, i) => {
    const pts = [[0, s.start], ...(r.trace ?? [])].map(([t, v]) => `${x(t).toFixed(1)},${y(v).toFixed(1)}`).join(" ");
    add("polyline", { points: pts, fill: "none", stroke: TRACE_COLOURS[i % TRACE_COLOURS.length], "stroke-width": 2, "data-series": `set ${i + 1}` });
  });
  const legend = h("div", { class: "legend", "aria-label": "Legend" },
    h("span", { style: "--c: #111" }, "target"),
    responses.map((r, i) => h("span", { style: `--c: ${TRACE_COLOURS[i % TRACE_COLOURS.length]}` }, `set ${i + 1}: P ${r.p}, D ${r.d}`)));
  return h("figure", { class: "step-figure" }, svg, legend);
}

function wckSection(studio) {
  const picker = devicePicker(studio, { families: ["wck"], label: "Servo" });
  const readAll = el("button", { type: "button" }, "Read settings");
  readAll.setAttribute("aria-label", "Read servo settings");
  const status = el("p", { className: "verify", "aria-live": "polite" });
  const body = el("div", { className: "params" });
  const runtimeWritten = new Map(); // "bus/id/param" -> values written at runtime by this page
  const inputs = new Map(); // param -> {field -> input}
  const eepromCells = new Map(); // param -> element
  const runtimeCells = new Map();

  const dev = () => picker.get();
  const key = (p) => {
    const d = dev();
    return `${d.bus}/${d.id}/${p}`;
  };

  function showValues(spec, cell, values) {
    if (!values) return cell.replaceChildren("—");
    cell.replaceChildren(...spec.fields.map(([, label, from]) => el("div", {}, `${label.replace(/ \(.*\)/, "")}: ${fmt(values[from], 2)}`)));
  }

  for (const spec of WCK_PARAMS) {
    const fieldInputs = {};
    const row = el("div", { className: "row" });
    for (const [name, label, , min, max, step] of spec.fields) {
      const input = numberInput({ min, max, step: step ?? 1 });
      fieldInputs[name] = input;
      row.append(field(label, input));
    }
    inputs.set(spec.param, fieldInputs);
    const request = (runtime) => {
      const d = dev();
      const req = { op: "wck.set", bus: d.bus, id: d.id, param: spec.param };
      for (const [name, label] of spec.fields) {
        const v = fieldInputs[name].value;
        if (v === "") throw new Error(`${label}: give a value (or read the settings first)`);
        req[name] = Number(v);
      }
      if (runtime) req.runtime = true;
      return req;
    };
    const write = async (runtime, button) => {
      let req;
      try {
        req = request(runtime);
      } catch (e) {
        studio.toast(e);
        return;
      }
      button.disabled = true;
      try {
        const rep = await studio.confirmAndRun(req);
        if (!rep) return;
        const problem = reportProblem(rep);
        if (problem) throw new Error(problem);
        const back = rep.results?.[0] ?? {};
        if (runtime) {
          runtimeWritten.set(key(spec.param), back);
          showValues(spec, runtimeCells.get(spec.param), back);
        } else {
          showValues(spec, eepromCells.get(spec.param), back);
        }
        status.textContent = `${spec.title} written ${runtime ? "at runtime" : "to EEPROM"}; read back: ${spec.fields.map(([, l, from]) => `${l} ${fmt(back[from], 2)}`).join(", ")}.`;
        studio.toast(`${spec.title}: written ${runtime ? "(runtime)" : "(EEPROM)"}`, "ok");
      } catch (e) {
        status.textContent = `${spec.title}: ${describeError(e)}`;
        studio.toast(e);
      } finally {
        button.disabled = studio.state.readOnly;
      }
    };
    const buttons = [];
    if (spec.runtime) {
      const b = el("button", { type: "button" }, "Runtime");
      b.setAttribute("aria-label", `Write ${spec.title} (runtime)`);
      b.addEventListener("click", () => write(true, b));
      buttons.push(writes(studio, b));
    }
    const e = el("button", { type: "button", className: "danger" }, "EEPROM");
    e.setAttribute("aria-label", `Write ${spec.title} to EEPROM`);
    e.addEventListener("click", () => write(false, e));
    buttons.push(writes(studio, e));
    const prev = el("button", { type: "button", className: "preview-btn" }, "Preview");
    prev.setAttribute("aria-label", `Preview ${spec.title} EEPROM write`);
    prev.addEventListener("click", () => {
      try {
        studio.preview(request(false));
      } catch (err) {
        studio.toast(err);
      }
    });
    buttons.push(prev);
    const eepromCell = el("div", { className: "value-cell" }, "—");
    const runtimeCell = el("div", { className: "value-cell" }, spec.runtime ? "—" : "(no runtime setting)");
    eepromCells.set(spec.param, eepromCell);
    runtimeCells.set(spec.param, runtimeCell);
    body.append(
      el("fieldset", { className: "param" }, [
        el("legend", {}, spec.title),
        el("div", { className: "param-edit" }, [row, el("div", { className: "row write" }, [el("span", { className: "hint" }, "Write:"), ...buttons])]),
        el("div", { className: "now" }, [
          el("div", {}, [el("span", { className: "tag" }, "EEPROM (read)"), eepromCell]),
          el("div", {}, [el("span", { className: "tag" }, "Runtime (written here)"), runtimeCell]),
        ]),
      ]),
    );
  }

  async function read() {
    const d = dev();
    if (!d) return;
    readAll.disabled = true;
    status.textContent = "reading…";
    const failures = [];
    for (const spec of WCK_PARAMS) {
      try {
        const rep = await studio.run({ op: "wck.get", bus: d.bus, param: spec.param, id: d.id });
        const r = rep.results?.[0];
        if (!r || r.kind) throw new Error(reportProblem(rep) ?? "no answer");
        showValues(spec, eepromCells.get(spec.param), r);
        for (const [name, , from] of spec.fields) inputs.get(spec.param)[name].value = r[from] ?? "";
      } catch (e) {
        failures.push(`${spec.title}: ${describeError(e)}`);
        showValues(spec, eepromCells.get(spec.param), null);
      }
    }
    for (const spec of WCK_PARAMS) {
      if (spec.runtime) showValues(spec, runtimeCells.get(spec.param), runtimeWritten.get(key(spec.param)) ?? null);
    }
    status.textContent = failures.length ? `Read failed: ${failures.join("; ")}` : `Read servo ${d.id} at ${new Date().toLocaleTimeString()}.`;
    readAll.disabled = false;
  }
  readAll.addEventListener("click", read);
  picker.onChange(read);
  queueMicrotask(read);

  return el("section", { className: "card", "aria-label": "wCK servo settings" }, [
    el("h3", {}, "wCK servo"),
    el("div", { className: "row" }, [picker.element, readAll]),
    el("p", { className: "hint" }, "The servo reports its EEPROM values only; the runtime column shows what this page last wrote at runtime (lost at power-off)."),
    status,
    body,
  ]);
}

function whjSection(studio) {
  const picker = devicePicker(studio, { families: ["whj"], label: "Joint" });
  const regInput = el("input", { type: "text", list: newId("regs"), size: 22, spellcheck: false, autocomplete: "off" });
  const datalist = el("datalist", { id: regInput.getAttribute("list") });
  const readBtn = el("button", { type: "button" }, "Read register");
  const value = el("input", { type: "number", step: "any", size: 10, className: "num" });
  const raw = el("input", { type: "checkbox", id: newId("raw") });
  const writeBtn = el("button", { type: "button", className: "danger" }, "Write register");
  const prevBtn = el("button", { type: "button", className: "preview-btn" }, "Preview");
  prevBtn.setAttribute("aria-label", "Preview register write");
  const info = el("div", { className: "reg-info", "aria-live": "polite" });
  const out = el("p", { className: "verify", "aria-live": "polite" });
  const tableBox = el("div", { className: "reg-table" }, "Loading the register table…");
  const valueLabel = el("label", { htmlFor: (value.id = newId("value")) }, "Value");
  let registers = [];
  const byName = new Map();
  const classes = new Map(); // name -> {cls, text}
  const valueCells = new Map(); // name -> td

  const reg = () => byName.get(regInput.value.trim().toUpperCase()) ?? null;
  const joint = () => picker.get();

  /** The safety class of a register, as the register table gives it (`safety`, `safety_note`). */
  function safetyClass(r) {
    if (!classes.has(r.name)) classes.set(r.name, { cls: r.safety, text: r.safety_note ?? "" });
    return classes.get(r.name);
  }

  function select_(r) {
    regInput.value = r.name;
    onRegister();
  }

  async function onRegister() {
    const r = reg();
    if (!r) {
      info.textContent = regInput.value ? "No register of that name." : "";
      valueLabel.textContent = "Value";
      return;
    }
    valueLabel.textContent = `Value (${raw.checked ? "raw counts" : r.unit || "no unit"})`;
    info.replaceChildren(
      el("strong", {}, `${r.name} (${hex(r.id)})`),
      ` ${r.meaning}. Unit: ${r.unit || "none"}${r.scale ? ` (×${r.scale} per count)` : ""}; ${r.writable ? "read-write" : "read-only"}${r.range ? `; range ${r.range[0]}…${r.range[1]}` : ""}; safety class: `,
      el("span", { className: "safety" }, "…"),
    );
    const c = safetyClass(r);
    if (reg() === r) info.querySelector(".safety").textContent = c.text ? `${c.cls} (${c.text})` : c.cls;
    writeBtn.disabled = !r.writable || studio.state.readOnly;
  }
  regInput.addEventListener("input", onRegister);
  raw.addEventListener("change", onRegister);

  async function readReg(name) {
    const d = joint();
    if (!d) return;
    try {
      const rep = await studio.run({ op: "whj.read", bus: d.bus, joints: String(d.id), register: name });
      const r = rep.results?.[0];
      if (!r || r.kind) throw new Error(reportProblem(rep) ?? "no answer");
      const text = r.value !== null && r.value !== undefined ? `${fmt(r.value, 4)} ${r.unit ?? ""}`.trim() + ` (raw ${r.raw})` : `raw ${r.raw}`;
      out.textContent = `Joint ${d.id} ${r.register} (${r.addr}) = ${text}.`;
      const cell = valueCells.get(r.register);
      if (cell) cell.textContent = text;
      return r;
    } catch (e) {
      out.textContent = `Read ${name}: ${describeError(e)}`;
      studio.toast(e);
      return null;
    }
  }

  // Every setting (the registers the joint keeps in flash) in one request, into the table.
  const readAllBtn = el("button", { type: "button", className: "secondary" }, "Read every setting");
  readAllBtn.addEventListener("click", async () => {
    const d = joint();
    if (!d) return;
    readAllBtn.disabled = true;
    try {
      const rep = await studio.run({ op: "whj.backup", bus: d.bus, joint: d.id });
      const row = rep.results?.[0];
      if (!row || row.kind) throw new Error(reportProblem(rep) ?? "no answer");
      for (const s of rep.summary?.settings ?? []) {
        const text = s.value !== null && s.value !== undefined ? `${fmt(s.value, 4)} ${s.unit ?? ""}`.trim() + ` (raw ${s.raw})` : `raw ${s.raw}`;
        // A 32-bit pair is one setting, shown on its low half's row.
        const cell = valueCells.get(s.register) ?? valueCells.get(`${s.register}_L`);
        if (cell) cell.textContent = text;
      }
      out.textContent = `Joint ${d.id}: ${rep.summary?.settings?.length ?? 0} settings read with one whj.backup.`;
    } catch (e) {
      out.textContent = `Read every setting: ${describeError(e)}`;
      studio.toast(e);
    } finally {
      readAllBtn.disabled = false;
    }
  });

  readBtn.addEventListener("click", () => {
    const r = reg();
    if (!r) return studio.toast(new Error(`no register named ${regInput.value || "(empty)"}`));
    readReg(r.name);
  });

  const writeRequest = () => {
    const r = reg();
    const d = joint();
    if (!r) throw new Error(`no register named ${regInput.value || "(empty)"}`);
    if (value.value === "") throw new Error("give the value to write");
    const req = { op: "whj.write", bus: d.bus, joints: String(d.id), register: r.name, value: Number(value.value) };
    if (raw.checked) req.raw = true;
    return req;
  };
  writeBtn.addEventListener("click", async () => {
    let req;
    try {
      req = writeRequest();
    } catch (e) {
      return studio.toast(e);
    }
    writeBtn.disabled = true;
    try {
      const rep = await studio.confirmAndRun(req);
      if (!rep) {
        out.textContent = "Cancelled: nothing was written.";
        return;
      }
      const problem = reportProblem(rep);
      if (problem) throw new Error(problem);
      const r = rep.results?.[0] ?? {};
      const text = r.value !== null && r.value !== undefined ? `${fmt(r.value, 4)} ${r.unit ?? ""}`.trim() + ` (raw ${r.raw})` : `raw ${r.raw}`;
      out.textContent = `Wrote joint ${r.id} ${r.register}; read back ${text}.`;
      const cell = valueCells.get(r.register);
      if (cell) cell.textContent = text;
      studio.toast(`${r.register}: written`, "ok");
    } catch (e) {
      out.textContent = `Write: ${describeError(e)}`;
      studio.toast(e);
    } finally {
      writeBtn.disabled = studio.state.readOnly;
    }
  });
  writes(studio, writeBtn);
  prevBtn.addEventListener("click", () => {
    try {
      studio.preview(writeRequest());
    } catch (e) {
      studio.toast(e);
    }
  });

  function renderTable() {
    const t = el("table", { className: "registers" }, [
      el("caption", {}, ["WHJ registers ", el("small", { className: "hint" }, "(select a name for its meaning and safety class)")]),
      el("thead", {}, el("tr", {}, ["Addr", "Name", "Unit", "Access", "Safety class", "Range", "Value", "Read"].map((h) => el("th", { scope: "col" }, h)))),
    ]);
    const body = el("tbody", {});
    for (const r of registers) {
      const cls = el("td", { className: "safety", title: r.safety_note ?? "" }, r.safety);
      const val = el("td", { className: "num" }, "");
      valueCells.set(r.name, val);
      const rb = el("button", { type: "button", className: "small", onclick: () => (select_(r), readReg(r.name)) }, "Read");
      rb.setAttribute("aria-label", `Read ${r.name}`);
      const pick = el("button", { type: "button", className: "link", title: r.meaning, onclick: () => select_(r) }, r.name);
      pick.setAttribute("aria-label", `Select ${r.name}`);
      body.append(
        el("tr", { className: r.writable ? "" : "ro" }, [
          el("td", { className: "num" }, hex(r.id)),
          el("td", { className: "nowrap" }, pick),
          el("td", {}, r.unit || ""),
          el("td", { className: "nowrap" }, r.writable ? "read-write" : "read-only"),
          cls,
          el("td", { className: "nowrap" }, r.range ? rangeText(r.range) : ""),
          val,
          el("td", {}, rb),
        ]),
      );
    }
    t.append(body);
    tableBox.replaceChildren(t);
  }

  studio
    .run({ op: "whj.registers" })
    .then((rep) => {
      registers = rep.results ?? [];
      for (const r of registers) {
        byName.set(r.name, r);
        datalist.append(el("option", { value: r.name }));
      }
      renderTable();
    })
    .catch((e) => {
      tableBox.textContent = `The register table could not be read: ${describeError(e)}`;
    });

  regInput.id = newId("reg");
  return el("section", { className: "card", "aria-label": "WHJ joint registers" }, [
    el("h3", {}, "WHJ joint registers"),
    el("div", { className: "row" }, [picker.element, field("Register", regInput), datalist, readBtn, readAllBtn]),
    el("div", { className: "row" }, [
      el("div", { className: "field" }, [valueLabel, value]),
      el("div", { className: "field check" }, [raw, el("label", { htmlFor: raw.id }, "Value in raw counts")]),
      writeBtn,
      prevBtn,
    ]),
    info,
    out,
    el("details", { className: "reg-details", open: true }, [el("summary", {}, "Register table"), tableBox]),
  ]);
}

/** A register's range; the full 32-bit range of a pair says nothing, so it shows as "32-bit". */
function rangeText([lo, hi]) {
  return lo === -2147483648 && hi === 2147483647 ? "32-bit" : `${lo} … ${hi}`;
}

function hex(n) {
  return `0x${Number(n).toString(16).padStart(2, "0")}`;
}
