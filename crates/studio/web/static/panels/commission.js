// Commission: forms over the catalogue's commissioning requests. wCK: wheel mode
// (`wck.wheel`) and the I/O (`wck.get` / `wck.set` `io`); WHJ: the CAN FD bit rates
// (`whj.set-rates`), the limits and gains (`whj.write` of the LIT_ / SEV_ registers, their
// safety class from the register table) and the end board (`whj.end-board`). Each form
// builds one request; the flow shows its dry run, asks where its class says so, runs it and
// draws its report.

import { h, devicePicker, select } from "../ui.js";
import { createFlow, flowButtons, labelled, boundedNumber, reportTable } from "./flow.js";

export default {
  id: "commission",
  title: "Commission",
  mount(root, studio) {
    root.append(
      h("h2", {}, "Commission"),
      h("p", { class: "lead" }, "wCK wheel mode and I/O; WHJ bit rates, limits and gains; the end board. Each form shows ",
        "its request's dry run before it runs; what writes EEPROM, flash or a register that needs confirming asks first."));
    const cols = h("div", { class: "columns" });
    root.append(cols);
    if (studio.buses("wck").length) cols.append(wheel(studio), io(studio));
    if (studio.buses("whj").length) cols.append(rates(studio), limits(studio), endBoard(studio));
  },
};

function card(title, ...children) {
  return h("section", { class: "card", "aria-label": title }, h("h3", {}, title), ...children);
}

function servo(studio, label) {
  const p = devicePicker(studio, { families: ["wck"], label: "Servo" });
  p.select.setAttribute("aria-label", label);
  return p;
}

function joint(studio, label) {
  const p = devicePicker(studio, { families: ["whj"], label: "Joint" });
  p.select.setAttribute("aria-label", label);
  return p;
}

function pick(p) {
  const d = p.get();
  if (!d) throw new Error("pick a device");
  return d;
}

function wheel(studio) {
  const p = servo(studio, "Wheel servo");
  const direction = select([["ccw", "counter-clockwise"], ["cw", "clockwise"]], "ccw");
  const speed = h("input", { type: "number", class: "num", min: 0, max: 15, value: 5 });
  const duration = h("input", { type: "number", class: "num", min: 0.1, max: 60, step: 0.1, value: 1 });
  const flow = createFlow(studio, { name: "Wheel", render: (rep) => reportTable("Wheel run", [["Servo", "id"], ["Rotations", "rotations"], ["Ran (ms)", "ran_ms"], ["Stopped", "stopped"], ["Stopped at", "stopped_at"], ["Load", "stopped_load"], ["Error", "error"]], rep.results ?? []) });
  return card("wCK wheel mode",
    h("p", { class: "hint" }, "The servo turns continuously for the given time, then stops in its safe state. It moves: arm first."),
    h("div", { class: "row" }, p.element, labelled("Direction", direction), labelled("Speed (0..15)", speed), labelled("Duration (s)", duration)),
    flowButtons(studio, flow, {
      label: "Turn",
      name: "Turn the wheel",
      long: true,
      build: () => {
        const d = pick(p);
        return { op: "wck.wheel", bus: d.bus, id: d.id, direction: direction.value, speed: boundedNumber(speed, "Speed", 0, 15), duration: boundedNumber(duration, "Duration (s)", 0.1, 60, { integer: false }) };
      },
    }),
    flow.element);
}

function io(studio) {
  const p = servo(studio, "I/O servo");
  const do1 = h("input", { type: "checkbox", id: "io-do1" });
  const do2 = h("input", { type: "checkbox", id: "io-do2" });
  const runtime = h("input", { type: "checkbox", id: "io-runtime", checked: true });
  const flow = createFlow(studio, {
    name: "I/O",
    render: (rep) => {
      const r = rep.results?.[0];
      if (r && !r.kind) {
        do1.checked = !!r.do1;
        do2.checked = !!r.do2;
      }
      return reportTable("I/O", [["Servo", "id"], ["Outputs", "outputs"], ["DO1", "do1"], ["DO2", "do2"], ["ADC", "adc"], ["ADC (V)", "adc_volts"], ["Error", "error"]], rep.results ?? []);
    },
  });
  return card("wCK I/O",
    h("div", { class: "row" }, p.element),
    flowButtons(studio, flow, {
      label: "Read I/O",
      name: "Read the I/O",
      changes: false,
      build: () => {
        const d = pick(p);
        return { op: "wck.get", bus: d.bus, param: "io", id: d.id };
      },
    }),
    h("div", { class: "row" },
      h("div", { class: "field check" }, do1, h("label", { for: "io-do1" }, "DO1 on")),
      h("div", { class: "field check" }, do2, h("label", { for: "io-do2" }, "DO2 on")),
      h("div", { class: "field check" }, runtime, h("label", { for: "io-runtime" }, "Runtime only (else EEPROM: asks first)"))),
    flowButtons(studio, flow, {
      label: "Write outputs",
      name: "Write the outputs",
      build: () => {
        const d = pick(p);
        const req = { op: "wck.set", bus: d.bus, param: "io", id: d.id, outputs: (do1.checked ? 1 : 0) | (do2.checked ? 2 : 0) };
        if (runtime.checked) req.runtime = true;
        return req;
      },
    }),
    flow.element);
}

function rates(studio) {
  const p = joint(studio, "Bit rate joint");
  const bitrate = select([250000, 500000, 1000000].map((b) => [b, `${b / 1000} kbit/s`]), 1000000);
  const dbitrate = select([250000, 500000, 1000000, 2000000, 4000000, 5000000].map((b) => [b, `${b / 1e6} Mbit/s`]), 5000000);
  bitrate.setAttribute("aria-label", "Arbitration bit rate");
  dbitrate.setAttribute("aria-label", "Data bit rate");
  const flow = createFlow(studio, {
    name: "Bit rates",
    render: (rep) => [
      reportTable("Bit rates", [["Joint", "id"], ["Before", "before"], ["After", "after"], ["Saved", "saved"], ["Error", "error"]], rep.results ?? []),
      rep.summary?.next ? h("pre", { class: "report" }, typeof rep.summary.next === "string" ? rep.summary.next : JSON.stringify(rep.summary.next, null, 2)) : null,
    ],
  });
  return card("WHJ bit rates",
    h("p", { class: "hint" }, "Written, read back and saved; the joint uses them after a power cycle (the adapter must follow). An enabled joint is refused."),
    h("div", { class: "row" }, p.element, labelled("Arbitration", bitrate), labelled("Data", dbitrate)),
    flowButtons(studio, flow, {
      label: "Write bit rates",
      name: "Write the bit rates",
      danger: true,
      build: () => {
        const d = pick(p);
        return { op: "whj.set-rates", bus: d.bus, joints: String(d.id), bitrate: Number(bitrate.value), dbitrate: Number(dbitrate.value) };
      },
    }),
    flow.element);
}

function limits(studio) {
  const p = joint(studio, "Limits joint");
  const reg = h("select", {});
  reg.setAttribute("aria-label", "Limit or gain");
  const value = h("input", { type: "number", class: "num", step: "any" });
  value.setAttribute("aria-label", "Limit or gain value");
  const about = h("p", { class: "hint", "aria-live": "polite" });
  const byName = new Map();
  const flow = createFlow(studio, { name: "Limits and gains", render: (rep) => reportTable("Register", [["Joint", "id"], ["Register", "register"], ["Addr", "addr"], ["Raw", "raw"], ["Value", "value"], ["Unit", "unit"]], rep.results ?? []) });
  const describe = () => {
    const r = byName.get(reg.value);
    if (!r) return;
    about.textContent = `${r.meaning.replace(/, low word$/, "")}. Unit: ${r.unit || "raw counts"}${r.range ? `; raw range ${r.range[0]}…${r.range[1]}` : ""}; safety class: ${r.safety}${r.safety_note ? ` (${r.safety_note})` : ""}.`;
  };
  reg.addEventListener("change", describe);
  studio.run({ op: "whj.registers" }).then((rep) => {
    for (const r of rep.results ?? []) {
      if (!r.writable || !/^(LIT|SEV)_/.test(r.name) || r.name.endsWith("_H")) continue;
      // A 32-bit pair is read and written as one value, named without its halves' _L / _H.
      const name = r.name.replace(/_L$/, "");
      byName.set(name, r);
      reg.append(h("option", { value: name }, `${name}${r.unit ? ` (${r.unit})` : ""}`));
    }
    describe();
  }).catch((e) => flow.say(`The register table could not be read: ${e.message}`, "error"));
  const target = () => {
    const d = pick(p);
    if (!byName.has(reg.value)) throw new Error("pick a limit or gain");
    return { bus: d.bus, joints: String(d.id), register: reg.value };
  };
  return card("WHJ limits and gains",
    h("div", { class: "row" }, p.element, labelled("Limit or gain", reg), labelled("Value (its unit; raw without one)", value)),
    about,
    flowButtons(studio, flow, { label: "Read", name: "Read the limit or gain", changes: false, build: () => ({ op: "whj.read", ...target() }) }),
    flowButtons(studio, flow, {
      label: "Write",
      name: "Write the limit or gain",
      danger: true,
      build: () => {
        const t = target();
        const text = value.value.trim();
        if (text === "" || !Number.isFinite(Number(text))) throw new Error(`${t.register}: give a number`);
        const req = { op: "whj.write", ...t, value: Number(text) };
        if (!byName.get(t.register).scale) req.raw = true;
        return req;
      },
    }),
    flow.element);
}

function endBoard(studio) {
  const buses = studio.buses("whj");
  const bus = select(buses);
  bus.setAttribute("aria-label", "End board bus");
  const action = select([["status", "read its state"], ["power", "tool power"], ["io", "an I/O channel's direction"], ["force", "read the force sensor"]], "status");
  action.setAttribute("aria-label", "End board action");
  const volts = select([[0, "off"], [12, "12 V"], [24, "24 V"]], 0);
  volts.setAttribute("aria-label", "Tool power");
  const channel = select([[1, "IO1"], [2, "IO2"]], 1);
  channel.setAttribute("aria-label", "Channel");
  const mode = select([["input", "input"], ["output", "output"]], "input");
  mode.setAttribute("aria-label", "Channel mode");
  const flow = createFlow(studio, {
    name: "End board",
    render: (rep) => {
      const r = rep.results?.[0] ?? {};
      return reportTable("End board", [["Field", 0], ["Value", 1]], Object.entries(r));
    },
  });
  const sync = () => {
    volts.closest(".field").hidden = action.value !== "power";
    channel.closest(".field").hidden = action.value !== "io";
    mode.closest(".field").hidden = action.value !== "io";
  };
  action.addEventListener("change", sync);
  const el = card("WHJ end board",
    h("p", { class: "hint" }, "The board at the arm's end: its state, the tool power, the direction of its two I/O channels, the force sensor."),
    h("div", { class: "row" }, buses.length > 1 ? labelled("Bus", bus) : null, labelled("Action", action), labelled("Tool power", volts), labelled("Channel", channel), labelled("Mode", mode)),
    flowButtons(studio, flow, {
      label: "Run",
      name: "Run the end-board action",
      build: () => {
        const req = { op: "whj.end-board", bus: bus.value, action: action.value };
        if (action.value === "power") req.volts = Number(volts.value);
        if (action.value === "io") Object.assign(req, { channel: Number(channel.value), mode: mode.value });
        return req;
      },
    }),
    flow.element);
  sync();
  return el;
}
