// Settings: one device's whole settings table, opened from a Bus scan row (or picked here).
// A wCK servo's parameter groups come from one `wck.backup`, a WHJ joint's settings (every
// register it keeps in flash) from one `whj.backup`, joined with the register table the
// library knows (`whj.registers`, nothing sent) for each one's meaning, range and safety
// class. Each value is edited in place; its write (`wck.set` / `whj.write`) goes through the
// flow: its dry run, its confirmation class (EEPROM, the dangerous register classes), the
// run and the read-back. The device's status is streamed beside the table while it shows.

import { h, fmt, devicePicker, describeError } from "../ui.js";
import { createFlow, flowButtons } from "./flow.js";

/** The wCK groups as `wck.set` takes them: [param, title, [[arg, label, backup field]]]. */
const WCK_GROUPS = [
  ["gains", "Position gains", [["p", "P gain", "p_gain"], ["d", "D gain", "d_gain"]]],
  ["i-gain", "I gain", [["i", "I gain", "i_gain"]]],
  ["speed", "Speed and acceleration", [["speed", "Speed", "speed"], ["accel", "Acceleration", "accel"]]],
  ["overload", "Overload", [["milliamps", "Threshold (mA)", "overload"]]],
  ["bounds", "Boundaries", [["lower", "Lower bound", "lower"], ["upper", "Upper bound", "upper"]]],
];

export default {
  id: "settings",
  title: "Settings",
  mount(root, studio) {
    const families = ["wck", "whj"].filter((f) => studio.buses(f).length);
    const picker = devicePicker(studio, { families, label: "Device" });
    picker.select.setAttribute("aria-label", "Settings device");
    const read = h("button", { type: "button" }, "Read all settings");
    const live = h("div", { class: "settings-live", "aria-label": "Live status", role: "group" });
    const liveStatus = h("span", { class: "stream-status" });
    const tableBox = h("div", { class: "settings-box" });
    const flow = createFlow(studio, { name: "Settings", render: () => null });
    let registers = null; // whj.registers rows by name
    let unsubscribe = null;
    let watchdog = null;
    let shown = false;
    let seq = 0; // the latest read: an earlier one that answers later is dropped

    root.append(
      h("h2", {}, "Settings"),
      h("p", { class: "lead" }, "A device's whole settings table, read at once (", h("code", {}, "wck.backup"), " / ",
        h("code", {}, "whj.backup"), ": one request) and edited in place. Every write shows its dry run first and asks ",
        "where its confirmation class says so (EEPROM, flash, the registers that need confirming); the table shows ",
        "the value read back. Click a row of a Bus scan to open its device here."),
      h("section", { class: "card", "aria-label": "Device settings" },
        h("div", { class: "row" }, picker.element, read),
        h("div", { class: "row" }, h("strong", {}, "Live: "), live, liveStatus),
        tableBox,
        flow.element));

    const device = () => picker.get();

    async function registerTable() {
      if (registers) return registers;
      const rep = await studio.run({ op: "whj.registers" });
      registers = new Map((rep.results ?? []).map((r) => [r.name, r]));
      return registers;
    }

    async function readAll() {
      const d = device();
      if (!d) return;
      const mine = ++seq;
      read.disabled = true;
      tableBox.replaceChildren(h("p", {}, `Reading every setting of ${noun(d)}…`));
      const request = d.family === "wck" ? { op: "wck.backup", bus: d.bus, id: d.id } : { op: "whj.backup", bus: d.bus, joint: d.id };
      try {
        const rep = await studio.run(request);
        const regs = d.family === "whj" ? await registerTable() : null;
        if (mine !== seq) return;
        const row = rep.results?.[0];
        if (!row || row.kind) throw new Error(row ? `${row.kind}: ${row.error}` : "no answer");
        if (d.family === "wck") wckTable(d, rep.summary);
        else whjTable(d, rep.summary, regs);
        flow.say(`Read ${noun(d)}'s settings at ${new Date().toLocaleTimeString()} (${request.op}, one request).`, "ok");
      } catch (e) {
        if (mine !== seq) return;
        tableBox.replaceChildren(h("p", { class: "fail" }, `Could not read ${noun(d)}: ${describeError(e)}`));
        flow.say(`${request.op} failed: ${describeError(e)}`, "error");
      } finally {
        read.disabled = false;
      }
    }

    function wckTable(d, s) {
      const rows = WCK_GROUPS.map(([param, title, fields]) => {
        const inputs = fields.map(([arg, label, from]) => {
          const input = h("input", { type: "number", class: "num", value: param === "overload" ? "" : s[from], placeholder: param === "overload" ? "400..1800" : "" });
          input.setAttribute("aria-label", `${label} of ${title}`);
          input.addEventListener("input", () => tr.classList.add("changed"));
          return [arg, label, input];
        });
        const build = () => {
          const req = { op: "wck.set", bus: d.bus, id: d.id, param };
          for (const [arg, label, input] of inputs) {
            if (input.value.trim() === "") throw new Error(`${title}: give the ${label}`);
            req[arg] = Number(input.value);
          }
          return req;
        };
        const value = h("td", { "data-group": param }, fields.map(([, label, from]) => `${label.replace(/ \(.*\)/, "")} ${param === "overload" ? `code ${s[from]}` : s[from]}`).join(", "));
        const buttons = flowButtons(studio, flow, {
          label: "Write",
          name: `Write ${title}`,
          build,
          danger: true,
          onReport: (rep) => {
            const back = rep.results?.[0];
            if (!back || back.kind) return;
            value.textContent = fields.map(([, label, from]) => {
              const k = from === "overload" ? "milliamps" : from;
              return `${label.replace(/ \(.*\)/, "")} ${back[k]}${from === "overload" ? ` mA (code ${back.overload_code})` : ""}`;
            }).join(", ");
            tr.classList.remove("changed");
          },
        });
        const tr = h("tr", {},
          h("th", { scope: "row" }, title),
          value,
          h("td", { class: "edit" }, inputs.map(([, label, input]) => h("label", { class: "mini" }, h("span", {}, label.replace(/ gain$/, "").replace("Threshold (mA)", "mA")), input))),
          h("td", { class: "safety-confirm" }, "EEPROM"),
          h("td", {}, buttons));
        return tr;
      });
      tableBox.replaceChildren(
        h("table", { class: "settings-table", "aria-label": `Settings of ${noun(d)}` },
          h("caption", {}, `Servo ${d.id} on ${d.bus}: its EEPROM parameter groups`),
          h("thead", {}, h("tr", {}, ["Group", "Read", "New value", "Confirmation", "Write"].map((c) => h("th", { scope: "col" }, c)))),
          h("tbody", {}, rows)));
    }

    function whjTable(d, s, regs) {
      const rows = (s.settings ?? []).map((setting) => {
        // A 32-bit pair is one setting, named without its halves' _L / _H.
        const info = regs.get(setting.register) ?? regs.get(`${setting.register}_L`) ?? {};
        const unit = setting.value == null ? "raw" : setting.unit;
        const input = h("input", { type: "number", class: "num", step: "any", value: setting.value ?? setting.raw });
        input.setAttribute("aria-label", `New value of ${setting.register}`);
        input.addEventListener("input", () => tr.classList.add("changed"));
        const value = h("td", { class: "num", "data-register": setting.register }, show(setting));
        const build = () => {
          const text = input.value.trim();
          if (text === "" || !Number.isFinite(Number(text))) throw new Error(`${setting.register}: give a number (${unit})`);
          const req = { op: "whj.write", bus: d.bus, joints: String(d.id), register: setting.register, value: Number(text) };
          if (setting.value == null) req.raw = true;
          return req;
        };
        const safety = info.safety ?? "plain";
        const tr = h("tr", { class: info.writable === false ? "ro" : "" },
          h("td", { class: "num" }, setting.addr),
          h("th", { scope: "row", title: info.meaning ?? "" }, setting.register),
          value,
          h("td", {}, setting.unit || ""),
          h("td", { class: "edit" }, info.writable === false ? "read-only" : input),
          h("td", { class: `safety-${safety}`, title: info.safety_note ?? "" }, safety),
          h("td", {}, info.writable === false || safety === "never" || safety === "motion" ? "" : flowButtons(studio, flow, {
            label: "Write",
            name: `Write ${setting.register}`,
            build,
            danger: safety !== "plain",
            onReport: (rep) => {
              const back = rep.results?.[0];
              if (!back || back.kind) return;
              value.textContent = show(back);
              tr.classList.remove("changed");
            },
          })));
        return tr;
      });
      const save = flowButtons(studio, flow, {
        label: "Save to flash",
        name: `Save joint ${d.id} to flash`,
        danger: true,
        build: () => ({ op: "whj.save", bus: d.bus, joints: String(d.id) }),
      });
      tableBox.replaceChildren(
        h("table", { class: "settings-table", "aria-label": `Settings of ${noun(d)}` },
          h("caption", {}, `Joint ${d.id} on ${d.bus} (${s.model}, firmware ${s.firmware}): ${rows.length} settings kept in flash`),
          h("thead", {}, h("tr", {}, ["Addr", "Register", "Read", "Unit", "New value", "Safety class", "Write"].map((c) => h("th", { scope: "col" }, c)))),
          h("tbody", {}, rows)),
        h("div", { class: "row" }, h("span", { class: "hint" }, "Writes change the joint until it is powered off; saving keeps them (a disabled joint only):"), save));
    }

    function liveStart() {
      liveStop();
      const d = device();
      if (!d || !shown) return;
      const request = d.family === "wck" ? { op: "wck.status", bus: d.bus, ids: String(d.id) } : { op: "whj.status", bus: d.bus, joints: String(d.id) };
      let last = 0;
      liveStatus.textContent = "waiting for the first reading…";
      unsubscribe = studio.subscribe("settings.live", request, 2, 2, (sample) => {
        last = performance.now();
        const row = sample.report?.results?.find((r) => String(r.id) === String(d.id));
        if (sample.failed || !row || row.kind) {
          live.replaceChildren(h("span", { class: "fail" }, `no reply: ${sample.error ?? row?.error ?? "no row for this device"}`));
          liveStatus.textContent = "";
          return;
        }
        const parts = d.family === "wck"
          ? [["position", `${row.position} steps`], ["angle", `${fmt(row.degrees, 1)}°`], ["load", row.load]]
          : [["enabled", row.enabled ? "yes" : "no"], ["mode", row.mode], ["position", `${fmt(row.position_deg, 2)}°`],
             ["current", row.current_ma == null ? "—" : `${row.current_ma} mA`], ["voltage", `${fmt(row.voltage_v, 1)} V`],
             ["temperature", `${fmt(row.temperature_c, 1)} °C`], ["error", row.error ?? "none"]];
        live.replaceChildren(...parts.map(([k, v]) => h("span", {}, `${k}: `, h("strong", {}, String(v)))));
        liveStatus.textContent = sample.late ? "late" : "live · 2 Hz";
        liveStatus.className = `stream-status ${sample.late ? "warn" : "ok"}`;
      });
      watchdog = setInterval(() => {
        if (last && performance.now() - last > 2000) {
          live.classList.add("stale");
          liveStatus.textContent = `stale: no reading for ${((performance.now() - last) / 1000).toFixed(1)} s`;
          liveStatus.className = "stream-status warn";
        } else live.classList.remove("stale");
      }, 500);
    }

    function liveStop() {
      unsubscribe?.();
      unsubscribe = null;
      clearInterval(watchdog);
      live.replaceChildren();
    }

    read.addEventListener("click", readAll);
    picker.onChange(() => {
      readAll();
      liveStart();
    });
    // A Bus scan row opens its device here: it leaves `studio.openSettings` ({family, bus,
    // id}) and shows this panel, which reads that device (and no other first).
    let readOnce = false;
    root.addEventListener("studio:show", () => {
      shown = true;
      const want = studio.openSettings;
      studio.openSettings = null;
      const now = device();
      const value = want && `${want.family}|${want.bus}|${want.id}`;
      if (want && (!now || `${now.family}|${now.bus}|${now.id}` !== value)) {
        picker.set(value); // reads it and starts its live status (onChange)
      } else {
        if (want || !readOnce) readAll();
        liveStart();
      }
      readOnce = true;
    });
    root.addEventListener("studio:hide", () => {
      shown = false;
      liveStop();
    });
  },
};

function noun(d) {
  return d.family === "wck" ? `servo ${d.id}` : `joint ${d.id}`;
}

function show(r) {
  return r.value != null ? `${fmt(r.value, 4)} (raw ${r.raw})` : `raw ${r.raw}`;
}

