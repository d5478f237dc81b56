// Device: one servo or joint up close: live readouts, jogging, and its actions.

import { el, field, select, fmt, devicePicker, action, rowText } from "../ui.js";
import { miniChart } from "../minichart.js";
import { deviceKey } from "../history.js";

export default {
  id: "device",
  title: "Device",
  mount(root, studio) {
    const firstWhj = studio.ids("whj")[0];
    const picker = devicePicker(studio, {
      label: "Device",
      initial: firstWhj ? `whj|${firstWhj.bus}|${firstWhj.id}` : undefined,
    });
    const readouts = el("section", { className: "card readouts", "aria-label": "Live readouts" });
    const jogBox = el("section", { className: "card jog", "aria-label": "Jog" });
    const actionsBox = el("section", { className: "card actions", "aria-label": "Actions" });
    const result = el("p", { className: "verify last-result", "aria-live": "polite" });
    root.append(
      el("h2", {}, "Device"),
      el("p", { className: "lead" }, "Live readings of one device, jogging (when armed) and its commands. Preview shows the exact packets or frames a command sends."),
      el("div", { className: "row" }, [picker.element]),
      el("div", { className: "columns" }, [readouts, el("div", {}, [jogBox, actionsBox])]),
    );

    let current = null; // {family, bus, id, teardown()}
    let visible = !root.hidden;
    const open = () => {
      current?.teardown();
      current = null;
      const d = picker.get();
      if (!d || !visible) return;
      current = d.family === "wck" ? wckView(studio, d, readouts, jogBox, actionsBox, result) : whjView(studio, d, readouts, jogBox, actionsBox, result);
    };
    picker.onChange(open);
    root.addEventListener("studio:show", () => {
      visible = true;
      if (!current) open();
    });
    root.addEventListener("studio:hide", () => {
      visible = false;
      current?.teardown();
      current = null;
    });
    open();
  },
};

/** A readout: label, value, unit; `set(v)`, `noReply()`, `stale(bool)`. */
function readout(label, unit, digits = 1) {
  const value = el("output", { className: "value" }, "—");
  value.setAttribute("aria-label", unit ? `${label} (${unit})` : label);
  const box = el("div", { className: "readout" }, [
    el("span", { className: "label" }, label),
    value,
    el("span", { className: "unit" }, unit ?? ""),
  ]);
  return {
    element: box,
    set(v) {
      value.textContent =
        typeof v === "boolean" ? (v ? "yes" : "no") : typeof v === "number" ? v.toFixed(digits) : fmt(v, digits);
      box.classList.remove("noreply", "stale");
    },
    noReply() {
      value.textContent = "no reply";
      box.classList.add("noreply");
    },
    stale(on) {
      box.classList.toggle("stale", on);
    },
  };
}

/**
 * A stream of readings shown in a group of readouts: subscribes, fills them from the
 * device's row, shows "no reply" when the read or the device failed, marks late samples
 * and data that stopped coming.
 */
function stream(studio, { name, request, rateHz, fields, status, onRow }) {
  let last = 0;
  let late = false;
  const period = 1000 / rateHz;
  const setStatus = (text, cls) => {
    status.textContent = text;
    status.className = `stream-status ${cls}`;
  };
  setStatus("waiting for the first reading…", "");
  const unsub = studio.subscribe(name, request, rateHz, Math.min(30, Math.max(1, rateHz)), (sample) => {
    last = performance.now();
    const row = sample.report?.results?.find((r) => String(r.id) === String(request.joints ?? request.ids));
    if (sample.failed || !row || row.kind) {
      const why = sample.error ?? row?.error ?? "no row for this device";
      for (const f of fields) f.r.noReply();
      setStatus(`no reply: ${why}`, "fail");
      onRow?.(null);
      return;
    }
    for (const f of fields) f.r.set(f.get(row));
    late = !!sample.late;
    setStatus(late ? `late: the bus could not keep ${rateHz} Hz` : `live · ${rateHz} Hz`, late ? "warn" : "ok");
    onRow?.(row);
  });
  const watchdog = setInterval(() => {
    const stale = last && performance.now() - last > Math.max(1500, 4 * period);
    for (const f of fields) f.r.stale(!!stale);
    if (stale) setStatus(`stale: no reading for ${((performance.now() - last) / 1000).toFixed(1)} s`, "warn");
  }, 500);
  return () => {
    unsub();
    clearInterval(watchdog);
  };
}

function group(title, fields, status) {
  return el("div", { className: "readout-group" }, [
    el("h3", {}, [title, " ", status]),
    el("div", { className: "readout-grid" }, fields.map((f) => f.r.element)),
  ]);
}

function wckView(studio, d, readouts, jogBox, actionsBox, result) {
  const noun = `servo ${d.id}`;
  const fields = [
    { r: readout("Position", "steps", 0), get: (r) => r.position },
    { r: readout("Angle", "deg", 2), get: (r) => r.degrees },
    { r: readout("Load", "", 0), get: (r) => r.load },
  ];
  const status = el("span", { className: "stream-status" });
  const chart = miniChart(studio, { name: "Position chart" });
  readouts.replaceChildren(el("h3", {}, `Servo ${d.id} on ${d.bus}`), group("Status", fields, status), chart.element);
  chart.show(deviceKey("wck", d.bus, d.id), "position", noun);
  const jog = jogger(studio, {
    family: "wck",
    d,
    unit: "steps",
    min: 0,
    max: 254,
    step: 1,
    steps: [1, 2, 4, 8],
    defaultStep: 4,
    box: jogBox,
    noun,
    eps: 0.5,
  });
  let position = null;
  const stop = stream(studio, {
    name: "device.wck",
    request: { op: "wck.status", bus: d.bus, ids: String(d.id) },
    rateHz: 10,
    fields,
    status,
    onRow: (row) => {
      position = row ? row.position : null;
      jog.position(position);
    },
  });
  // The servo's own boundaries narrow the jog range.
  studio
    .run({ op: "wck.get", bus: d.bus, param: "bounds", id: d.id })
    .then((rep) => {
      const b = rep.results?.[0];
      if (b && !b.kind) jog.limits(b.lower, b.upper);
    })
    .catch(() => {});

  const torque = select([[0, "0 (strongest)"], 1, 2, 3, [4, "4 (weakest)"]], 2);
  const show = (rep) => {
    const r = rep.results?.[0];
    result.textContent = r ? `Last result, ${rep.op}: ${rowText(r)}` : `Last result, ${rep.op}: done`;
  };
  const acts = [
    action(studio, { label: "Passive", name: `Passive ${noun}`, request: () => ({ op: "wck.passive", bus: d.bus, ids: String(d.id) }), onReport: show }),
    action(studio, {
      label: "Hold",
      name: `Hold ${noun} at its position`,
      request: () => {
        if (position === null) throw new Error(`no position of ${noun} yet: hold needs its present position`);
        return { op: "wck.move", bus: d.bus, id: d.id, position, torque: Number(torque.value) };
      },
      onReport: show,
    }),
    action(studio, { label: "Break", name: "Break (every servo on the bus)", request: () => ({ op: "wck.brake", bus: d.bus }), onReport: show }),
  ];
  actionsBox.replaceChildren(
    el("h3", {}, "Commands"),
    el("div", { className: "row" }, [acts[0].element, acts[1].element, field("Hold torque", torque)]),
    el("div", { className: "row" }, [acts[2].element]),
    el("p", { className: "hint" }, "Passive releases the torque. Hold keeps the present position (needs Arm). Break stops every servo on the bus."),
    result,
  );
  result.textContent = "";
  return {
    teardown() {
      stop();
      jog.teardown();
      chart.teardown();
    },
  };
}

function whjView(studio, d, readouts, jogBox, actionsBox, result) {
  const noun = `joint ${d.id}`;
  const fast = [
    { r: readout("Position", "deg", 2), get: (r) => r.position_deg },
    { r: readout("Speed", "rpm", 2), get: (r) => r.speed_rpm },
    { r: readout("Current", "mA", 0), get: (r) => r.current_ma },
  ];
  const slow = [
    { r: readout("Voltage", "V", 2), get: (r) => r.voltage_v },
    { r: readout("Temperature", "°C", 1), get: (r) => r.temperature_c },
    { r: readout("Enabled", "", 0), get: (r) => r.enabled },
    { r: readout("Mode", "", 0), get: (r) => r.mode },
    { r: readout("Brake", "", 0), get: (r) => r.brake },
    { r: readout("Error bits", "", 0), get: (r) => r.error },
  ];
  const chart = miniChart(studio, { name: "Position chart" });
  const fastStatus = el("span", { className: "stream-status" });
  const slowStatus = el("span", { className: "stream-status" });
  readouts.replaceChildren(
    el("h3", {}, `Joint ${d.id} on ${d.bus}`),
    group("Motion", fast, fastStatus),
    group("Status", slow, slowStatus),
    chart.element,
  );
  chart.show(deviceKey("whj", d.bus, d.id), "position", noun);
  const jog = jogger(studio, {
    family: "whj",
    d,
    unit: "deg",
    min: -360,
    max: 360,
    step: 0.1,
    steps: [0.1, 0.5, 1, 2],
    defaultStep: 1,
    box: jogBox,
    noun,
    eps: 0.05,
  });
  const mode = select(["position", "speed", "current", "open-loop"], "position");
  // The joint's mode from its status, until the user picks one: the pick then stays until
  // Set mode has sent it and its report is back, whether or not the list still has the
  // focus (a click on Set mode takes the focus first, and a status arriving between the
  // two must not put the old mode back into the request).
  let picked = null; // the mode the user picked, until Set mode's report for it is back
  let sent = null; // the mode the last Set mode sent
  mode.addEventListener("change", () => {
    picked = mode.value;
  });
  const stops = [
    stream(studio, {
      name: "device.whj.sample",
      request: { op: "whj.sample", bus: d.bus, joints: String(d.id) },
      rateHz: 20,
      fields: fast,
      status: fastStatus,
      onRow: (row) => jog.position(row ? row.position_deg : null),
    }),
    stream(studio, {
      name: "device.whj.status",
      request: { op: "whj.status", bus: d.bus, joints: String(d.id) },
      rateHz: 2,
      fields: slow,
      status: slowStatus,
      onRow: (row) => {
        if (row?.mode && picked === null && document.activeElement !== mode) mode.value = row.mode;
      },
    }),
  ];
  studio
    .run({ op: "whj.info", bus: d.bus, joint: d.id })
    .then((rep) => {
      const i = rep.results?.[0];
      if (i && !i.kind && i.min_deg !== undefined) jog.limits(i.min_deg, i.max_deg);
    })
    .catch(() => {});

  const show = (rep) => {
    const r = rep.results?.[0];
    result.textContent = r ? `Last result, ${rep.op}: ${rowText(r)}` : `Last result, ${rep.op}: done`;
  };
  const joints = String(d.id);
  const a = (label, name, request, className = "") =>
    action(studio, { label, name: `${name} ${noun}`, request, onReport: show, className }).element;
  actionsBox.replaceChildren(
    el("h3", {}, "Commands"),
    el("div", { className: "row" }, [
      a("Enable", "Enable", () => ({ op: "whj.enable", bus: d.bus, joints })),
      a("Disable", "Disable", () => ({ op: "whj.disable", bus: d.bus, joints })),
      a("Clear errors", "Clear errors of", () => ({ op: "whj.clear", bus: d.bus, joints })),
    ]),
    el("div", { className: "row" }, [
      field("New mode", mode),
      action(studio, {
        label: "Set mode",
        name: `Set mode of ${noun}`,
        request: () => {
          sent = mode.value;
          return { op: "whj.mode", bus: d.bus, joints, mode: sent };
        },
        onReport: (rep) => {
          // A pick made since is kept.
          if (picked === sent) picked = null;
          show(rep);
        },
      }).element,
    ]),
    el("div", { className: "row" }, [
      a("Zero", "Zero the position of", () => ({ op: "whj.zero", bus: d.bus, joint: d.id })),
      a("Save", "Save to flash", () => ({ op: "whj.save", bus: d.bus, joints }), "danger"),
    ]),
    el("p", { className: "hint" }, "Enable needs Arm. Zero makes the present position 0°. Save writes the joint's settings to flash (it must be disabled)."),
    result,
  );
  result.textContent = "";
  return {
    teardown() {
      for (const s of stops) s();
      jog.teardown();
      chart.teardown();
    },
  };
}

/**
 * The jog controls: a slider for the target and "Jog −" / "Jog +" buttons. While the
 * slider is away from the device, or a button is held, one jog goes every 100 ms (the
 * server moves at most one jog step from where the device is). Only while armed.
 */
function jogger(studio, { family, d, unit, min, max, step, steps, defaultStep, box, noun, eps }) {
  const slider = el("input", { type: "range", min, max, step, value: family === "wck" ? 127 : 0, disabled: true });
  const sliderLabel = `Jog target ${noun} (${unit})`;
  slider.setAttribute("aria-label", sliderLabel);
  const targetOut = el("output", { className: "value" }, Number(slider.value).toFixed(family === "wck" ? 0 : 1));
  const stepSel = select(steps.map((s) => [s, `${s} ${unit}`]), defaultStep);
  const minus = el("button", { type: "button", disabled: true }, "Jog −");
  const plus = el("button", { type: "button", disabled: true }, "Jog +");
  minus.setAttribute("aria-label", `Jog − (${noun} down one step)`);
  plus.setAttribute("aria-label", `Jog + (${noun} up one step)`);
  const note = el("p", { className: "hint", "aria-live": "polite" });
  const limitsNote = el("small", { className: "hint" }, `${min} … ${max} ${unit}`);

  let pos = null; // the device's last known position (unit)
  let goal = null; // the slider's target while jogging
  let hold = 0; // −1 / +1 while a button is held
  let holdStart = 0;
  let pressBase = null;
  let lastSent = null;
  let stuck = 0;
  let inflight = false;
  let timer = null;
  let dragging = false;
  let followAfter = 0;

  const digits = family === "wck" ? 0 : 1;
  const clamp = (v) => Math.min(Number(slider.max), Math.max(Number(slider.min), v));
  const canJog = () => studio.state.armed && studio.state.controller && studio.state.connected;
  const showTarget = (v) => {
    targetOut.textContent = Number(v).toFixed(digits);
  };

  function update() {
    const ok = canJog();
    slider.disabled = minus.disabled = plus.disabled = !ok;
    note.textContent = ok ? "" : studio.state.readOnly ? "Read-only studio: no jogging." : "Arm to jog.";
    if (!ok) halt();
  }
  const offState = studio.on("state", update);

  function start() {
    if (!timer && canJog()) {
      timer = setInterval(tick, 100);
      tick();
    }
  }
  function halt() {
    if (timer) clearInterval(timer);
    timer = null;
    goal = null;
    hold = 0;
    stuck = 0;
  }

  async function tick() {
    if (!canJog()) return halt();
    if (inflight) return;
    let target;
    if (hold) {
      const base = lastSent ?? pos;
      if (base === null) return;
      target = clamp(base + hold * Number(stepSel.value));
    } else if (goal !== null) {
      target = goal;
    } else {
      return halt();
    }
    if (family === "wck") target = Math.round(target);
    inflight = true;
    try {
      const j = await studio.jog(family, d.bus, d.id, target);
      const sent = Number(j.sent);
      if (lastSent !== null && Math.abs(sent - lastSent) < eps / 2 && !hold) stuck++;
      else stuck = 0;
      lastSent = sent;
      if (hold) {
        slider.value = String(sent);
        showTarget(sent);
      }
      if (!hold && goal !== null && Math.abs(sent - goal) < eps) {
        // The goal itself is commanded: the device gets there on its own.
        followAfter = performance.now() + 1500;
        halt();
      } else if (!hold && stuck >= 3) {
        note.textContent = `Stopped at ${fmt(sent, digits)} ${unit}${j.limited ? ": a limit was reached" : ""}.`;
        slider.value = String(sent);
        showTarget(sent);
        followAfter = performance.now() + 1500;
        halt();
      }
    } catch (e) {
      halt();
      studio.toast(e);
    } finally {
      inflight = false;
    }
  }

  slider.addEventListener("input", () => {
    goal = Number(slider.value);
    showTarget(goal);
    start();
  });
  slider.addEventListener("pointerdown", () => (dragging = true));
  const up = () => (dragging = false);
  addEventListener("pointerup", up);
  addEventListener("pointercancel", up);

  for (const [b, dir] of [
    [minus, -1],
    [plus, 1],
  ]) {
    b.addEventListener("pointerdown", (e) => {
      if (b.disabled || e.button !== 0) return;
      b.setPointerCapture?.(e.pointerId);
      pressBase = lastSent ?? pos;
      hold = dir;
      goal = null;
      holdStart = performance.now();
      start();
    });
    const release = () => {
      if (hold !== dir) return;
      hold = 0;
      if (performance.now() - holdStart < 300 && pressBase !== null) {
        goal = clamp(pressBase + dir * Number(stepSel.value)); // a short press: one step
        if (family === "wck") goal = Math.round(goal);
        slider.value = String(goal);
        showTarget(goal);
        start();
      } else {
        goal = null;
        followAfter = performance.now() + 1500;
      }
    };
    b.addEventListener("pointerup", release);
    b.addEventListener("pointercancel", release);
    b.addEventListener("lostpointercapture", release);
    b.addEventListener("click", (e) => {
      if (e.detail !== 0) return; // pointer presses are handled above
      const base = goal ?? lastSent ?? pos; // keyboard: one step per press
      if (base === null) return;
      goal = clamp(base + dir * Number(stepSel.value));
      if (family === "wck") goal = Math.round(goal);
      slider.value = String(goal);
      showTarget(goal);
      start();
    });
  }

  update();
  box.replaceChildren(
    el("h3", {}, `Jog ${noun}`),
    el("div", { className: "jog-row" }, [
      el("label", { htmlFor: (slider.id = `jog-${family}-${d.id}`) }, sliderLabel),
      el("div", { className: "row" }, [slider, targetOut, el("span", { className: "unit" }, unit)]),
      limitsNote,
    ]),
    el("div", { className: "row" }, [minus, plus, field("Jog step", stepSel)]),
    note,
  );
  slider.removeAttribute("aria-label"); // the <label for> names it

  return {
    position(p) {
      pos = p;
      if (p === null) return;
      const idle = goal === null && !hold && !dragging && !timer;
      const settled = lastSent === null || Math.abs(p - lastSent) < Math.max(eps, 0.5) || performance.now() > followAfter;
      if (idle && settled ) {
        slider.value = String(p);
        showTarget(p);
      }
    },
    limits(lo, hi) {
      slider.min = String(lo);
      slider.max = String(hi);
      limitsNote.textContent = `${fmt(lo, digits)} … ${fmt(hi, digits)} ${unit}`;
    },
    teardown() {
      halt();
      offState();
      removeEventListener("pointerup", up);
      removeEventListener("pointercancel", up);
    },
  };
}

