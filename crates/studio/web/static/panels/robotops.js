// Robot: forms over the robot file's requests. Calibration (`robot.calibrate`: move the
// joints through their range by hand, the zero and limits it finds), teaching
// (`robot.teach`: record a trajectory by moving the limp joints; it asks first), trajectory
// play with its record (`robot.play`: per joint what was sent and how closely it tracked)
// and teleoperation (`robot.teleop`: followers driven by leaders, until stopped). Each
// builds one request; the flow shows its dry run, asks where its class says so, runs it
// with its progress and a Stop button, and draws its report.

import { h, fmt } from "../ui.js";
import { createFlow, flowButtons, labelled, boundedNumber, reportTable } from "./flow.js";

export default {
  id: "robotops",
  title: "Robot",
  mount(root, studio) {
    const names = ["wck", "whj"].flatMap((f) => studio.ids(f)).map((d) => d.name).filter(Boolean);
    root.append(
      h("h2", {}, "Robot"),
      h("p", { class: "lead" }, "Calibration, teaching, trajectory play and teleoperation of the robot file's joints (by name: ",
        names.length ? names.join(", ") : "this studio has no robot file", "). Each shows its dry run before it runs; what moves needs arming, ",
        "teaching asks first (the joints go limp); Stop or the stop key ends a run in the robot file's safe state."));
    if (!names.length) return;
    const trajectory = h("textarea", { rows: 7, class: "request-json", spellcheck: "false" });
    trajectory.setAttribute("aria-label", "Trajectory");
    const whj = studio.ids("whj").map((d) => d.name).filter(Boolean);
    const first = whj[0] ?? names[0];
    trajectory.value = `time_s,${first}\n0,0\n1,10\n2,0\n`;
    const cols = h("div", { class: "columns wide-cards" });
    root.append(cols);
    cols.append(calibrate(studio), teach(studio, names, trajectory), play(studio, trajectory), teleop(studio, names));
  },
};

/** The most leader → follower pairs a teleoperation takes (`robot.teleop`'s `map`). */
const MAX_PAIRS = 64;

function card(title, ...children) {
  return h("section", { class: "card", "aria-label": title }, h("h3", {}, title), ...children);
}

/** The per-joint rows of a robot report and its summary's scalar facts. */
function robotReport(caption, columns) {
  return (rep) => {
    const s = rep.summary ?? {};
    const facts = Object.entries(s).filter(([, v]) => v === null || typeof v !== "object");
    return [
      rep.failed ? h("p", { class: "fail" }, `${rep.failed}: ${rep.error ?? "failed"}`) : null,
      reportTable(caption, [["Joint", "id"], ...columns, ["Error", "error"]], rep.results ?? []),
      facts.length ? h("p", { class: "hint", "data-field": "summary" }, facts.map(([k, v]) => `${k.replaceAll("_", " ")}: ${typeof v === "number" ? fmt(v, 3) : v}`).join(" · ")) : null,
    ];
  };
}

function calibrate(studio) {
  const seconds = h("input", { type: "number", class: "num", min: 0.1, max: 600, step: 0.1, value: 2 });
  const rate = h("input", { type: "number", class: "num", min: 1, max: 100, value: 20 });
  const zero = h("select", {}, h("option", { value: "keep" }, "keep the file's zero"), h("option", { value: "end" }, "the pose at the end"));
  const margin = h("input", { type: "number", class: "num", min: 0, max: 30, step: 0.5, value: 2 });
  const flow = createFlow(studio, {
    name: "Calibration",
    render: robotReport("Calibration", [["Samples", "samples"], ["Min (°)", "min_deg"], ["Max (°)", "max_deg"], ["Zero (°)", "zero_deg"], ["Offset (rad)", "offset_rad"], ["Limits (rad)", "limits_rad"]]),
  });
  return card("Calibration",
    h("p", { class: "hint" }, "Move each joint by hand through its range while it records; the report gives the zero and the limits for the robot file (the file is not written: robobus robot calibrate --write does)."),
    h("div", { class: "row" }, labelled("Seconds", seconds), labelled("Rate (Hz)", rate), labelled("Zero", zero), labelled("Margin (°)", margin)),
    flowButtons(studio, flow, {
      label: "Calibrate",
      name: "Run the calibration",
      long: true,
      build: () => ({
        op: "robot.calibrate",
        seconds: boundedNumber(seconds, "Seconds", 0.1, 600, { integer: false }),
        rate_hz: boundedNumber(rate, "Rate (Hz)", 1, 100, { integer: false }),
        zero: zero.value,
        margin_deg: boundedNumber(margin, "Margin (°)", 0, 30, { integer: false }),
      }),
    }),
    flow.element);
}

function teach(studio, names, trajectory) {
  const seconds = h("input", { type: "number", class: "num", min: 0.1, max: 3600, step: 0.1, value: 2 });
  const rate = h("input", { type: "number", class: "num", min: 1, max: 100, value: 20 });
  const joints = h("input", { type: "text", size: 24, placeholder: "every joint", spellcheck: "false" });
  const flow = createFlow(studio, {
    name: "Teaching",
    render: (rep, req) => {
      const drawn = robotReport("Teaching", [["Samples", "samples"], ["Min (°)", "min_deg"], ["Max (°)", "max_deg"], ["Ended", "ended"]])(rep, req);
      const t = rep.summary?.trajectory;
      if (typeof t === "string" && t) {
        trajectory.value = t;
        drawn.push(h("p", { class: "ok" }, `The recorded trajectory (${rep.summary.points} points) is in the Trajectory play form.`));
      }
      return drawn;
    },
  });
  return card("Teaching",
    h("p", { class: "hint" }, "The joints go limp (wCK passive, WHJ in current mode at the hold current) and their positions are recorded while you move them; the recording becomes a trajectory to play. It asks first."),
    h("div", { class: "row" }, labelled("Seconds", seconds), labelled("Rate (Hz)", rate), labelled("Joints (names, comma-separated)", joints)),
    flowButtons(studio, flow, {
      label: "Teach",
      name: "Record a trajectory",
      long: true,
      danger: true,
      build: () => {
        const req = {
          op: "robot.teach",
          seconds: boundedNumber(seconds, "Seconds", 0.1, 3600, { integer: false }),
          rate_hz: boundedNumber(rate, "Rate (Hz)", 1, 100, { integer: false }),
        };
        const list = joints.value.split(",").map((s) => s.trim()).filter(Boolean);
        const unknown = list.filter((n) => !names.includes(n));
        if (unknown.length) throw new Error(`Joints: ${unknown.join(", ")} ${unknown.length === 1 ? "is" : "are"} not in the robot file (${names.join(", ")})`);
        if (list.length) req.joints = list;
        return req;
      },
    }),
    flow.element);
}

function play(studio, trajectory) {
  const rate = h("input", { type: "number", class: "num", min: 1, max: 500, value: 50 });
  const torque = h("input", { type: "number", class: "num", min: 0, max: 4, value: 2 });
  const flow = createFlow(studio, {
    name: "Trajectory play",
    render: robotReport("Play record", [["Commands", "commands"], ["Limited", "limited"], ["Failed", "failed"], ["Start (°)", "start_deg"], ["Target (°)", "target_deg"], ["Position (°)", "position_deg"], ["Tracking max (°)", "tracking_max_deg"], ["Tracking RMS (°)", "tracking_rms_deg"]]),
  });
  return card("Trajectory play",
    h("p", { class: "hint" }, "A trajectory file: time_s, then a column per joint of the robot file (degrees). It is checked against the robot file and the joints' limits before anything moves; arm first."),
    labelled("Trajectory", trajectory),
    h("div", { class: "row" }, labelled("Rate (Hz)", rate), labelled("wCK torque", torque)),
    flowButtons(studio, flow, {
      label: "Play",
      name: "Play the trajectory",
      long: true,
      build: () => {
        if (!trajectory.value.trim()) throw new Error("Trajectory: give a trajectory file's text (or teach one)");
        return { op: "robot.play", trajectory: trajectory.value, rate_hz: boundedNumber(rate, "Rate (Hz)", 1, 500, { integer: false }), torque: boundedNumber(torque, "wCK torque", 0, 4) };
      },
    }),
    flow.element);
}

function teleop(studio, names) {
  const rows = h("tbody", {});
  const addPair = (leader = "", follower = "") => {
    if (rows.children.length >= MAX_PAIRS) {
      studio.toast(`At most ${MAX_PAIRS} leader → follower pairs (robot.teleop's bound).`, "error");
      return;
    }
    const l = h("select", {}, names.map((n) => h("option", { value: n }, n)));
    const f = h("select", {}, names.map((n) => h("option", { value: n }, n)));
    const scale = h("input", { type: "number", class: "num", min: -10, max: 10, step: 0.1, value: 1 });
    const offset = h("input", { type: "number", class: "num", min: -360, max: 360, step: 0.5, value: 0 });
    if (leader) l.value = leader;
    if (follower) f.value = follower;
    const i = rows.children.length + 1;
    l.setAttribute("aria-label", `Leader ${i}`);
    f.setAttribute("aria-label", `Follower ${i}`);
    scale.setAttribute("aria-label", `Scale ${i}`);
    offset.setAttribute("aria-label", `Offset ${i}`);
    const remove = h("button", { type: "button", class: "small secondary", onclick: () => tr.remove() }, "Remove");
    const tr = h("tr", {}, h("td", {}, l), h("td", {}, f), h("td", {}, scale), h("td", {}, offset), h("td", {}, remove));
    rows.append(tr);
  };
  const whj = studio.ids("whj").map((d) => d.name).filter(Boolean);
  addPair(whj[0] ?? names[0], whj[1] ?? names[1] ?? names[0]);
  const rate = h("input", { type: "number", class: "num", min: 1, max: 200, value: 50 });
  const seconds = h("input", { type: "number", class: "num", min: 0.1, max: 86400, step: 0.1, placeholder: "until stopped" });
  const flow = createFlow(studio, {
    name: "Teleoperation",
    render: robotReport("Teleoperation", [["Leader", "leader"], ["Commands", "commands"], ["Limited", "limited"], ["Target (°)", "target_deg"], ["Position (°)", "position_deg"], ["Tracking max (°)", "tracking_max_deg"], ["Tracking RMS (°)", "tracking_rms_deg"]]),
  });
  return card("Teleoperation",
    h("p", { class: "hint" }, "Each follower joint follows its leader (scaled, offset), the leaders limp; without a time it runs until stopped. Arm first."),
    h("table", { class: "pairs" },
      h("caption", {}, "Leader → follower pairs"),
      h("thead", {}, h("tr", {}, ["Leader", "Follower", "Scale", "Offset (°)", ""].map((c) => h("th", { scope: "col" }, c)))),
      rows),
    h("div", { class: "row" }, h("button", { type: "button", class: "secondary", onclick: () => addPair() }, "Add a pair"), labelled("Rate (Hz)", rate), labelled("Seconds", seconds)),
    flowButtons(studio, flow, {
      label: "Teleoperate",
      name: "Start the teleoperation",
      long: true,
      build: () => {
        const map = [...rows.children].map((tr, i) => {
          const [l, f] = tr.querySelectorAll("select");
          const [scale, offset] = tr.querySelectorAll("input");
          return { leader: l.value, follower: f.value, scale: boundedNumber(scale, `Scale ${i + 1}`, -10, 10, { integer: false }), offset_deg: boundedNumber(offset, `Offset ${i + 1}`, -360, 360, { integer: false }) };
        });
        if (!map.length) throw new Error("add a leader → follower pair");
        const req = { op: "robot.teleop", map, rate_hz: boundedNumber(rate, "Rate (Hz)", 1, 200, { integer: false }) };
        if (seconds.value.trim() !== "") req.seconds = boundedNumber(seconds, "Seconds", 0.1, 86400, { integer: false });
        return req;
      },
    }),
    flow.element);
}
