// The commissioning panels' one way to run a request: form → request → dry run →
// confirmation → run → report. A panel builds the catalogue request from its form; the flow
// shows the request's dry run (its effect, its confirmation class and the exact bytes or
// frames, as Preview does) before anything is sent, asks through the studio's confirmation
// dialog when the plan says so, runs it (over the WebSocket with its progress when it is
// long) and hands the report back to the panel to draw. Nothing here knows a device: the
// plan and the report are the server's.

import { h, panelStyles, reportProblem, describeError, writes } from "../ui.js";

/** How much of a request (its JSON) and of a failure the status line shows; the report has it all. */
const MAX_SHOWN = 400;

function clip(text) {
  return text.length > MAX_SHOWN ? `${text.slice(0, MAX_SHOWN)}… (the report below has it all)` : text;
}

const EFFECTS = {
  read: "read: changes nothing on a device",
  configure: "configure: changes a setting, moves nothing",
  motion: "motion: moves or energises a device (needs arming)",
};

/**
 * A flow box: the dry run of the last request (effect, confirmation class, frames), a
 * status line, a progress bar and a Stop button for long runs, and the report's place.
 * `name` labels it ("Settings"); `render(report, request)` draws a report (default: JSON).
 * Returns {element, dryRun(request), run(request, {long}), say(text, kind), stop()}.
 */
export function createFlow(studio, { name, render } = {}) {
  panelStyles("preview");
  panelStyles("flow");
  const effect = h("dd", { "data-field": "effect" }, "–");
  const confirm = h("dd", { "data-field": "confirm" }, "–");
  const steps = h("dd", { "data-field": "steps" }, "–");
  const frames = h("pre", { class: "frames", "aria-label": `${name} dry run: bytes and frames`, tabindex: 0 });
  const status = h("p", { role: "status", "aria-live": "polite", class: "summary flow-status" });
  const progress = h("progress", { "aria-label": `${name} progress`, max: 1, value: 0, hidden: true });
  const stopBtn = h("button", { type: "button", class: "danger", hidden: true, onclick: () => handle?.stop() }, "Stop");
  stopBtn.setAttribute("aria-label", `Stop ${name}`);
  const report = h("div", { class: "flow-report", "aria-label": `${name} report` });
  const requestLine = h("code", { class: "flow-request" });
  let handle = null;

  const element = h("div", { class: "flow" },
    h("div", { class: "row" }, progress, stopBtn),
    status,
    h("details", { class: "flow-plan", hidden: true },
      h("summary", {}, "Dry run: ", requestLine),
      h("dl", { class: "plan-facts" },
        h("dt", {}, "Effect"), effect,
        h("dt", {}, "Confirmation"), confirm,
        h("dt", {}, "Steps"), steps),
      frames),
    report);
  element.setAttribute("aria-label", `${name} flow`);
  element.setAttribute("role", "group");

  function say(text, kind = "info") {
    status.textContent = text;
    status.className = `summary flow-status ${kind === "error" ? "fail" : kind === "ok" ? "ok" : ""}`;
  }

  /** Show a request's dry run; returns the plan view, or null (refused: the error shown). */
  async function dryRun(request) {
    const text = JSON.stringify(request);
    requestLine.textContent = text.length > MAX_SHOWN ? `${text.slice(0, MAX_SHOWN)}… (${text.length} characters)` : text;
    try {
      const p = await studio.plan(request);
      effect.textContent = EFFECTS[p.effect] ?? p.effect ?? "–";
      effect.dataset.value = p.effect ?? "";
      const cls = p.confirm ?? (p.ask == null ? "none" : "yes");
      confirm.textContent = p.ask == null ? "none: runs without asking" : `${cls}: ${p.ask}`;
      confirm.dataset.value = cls;
      const n = p.steps?.length ?? 0;
      steps.textContent = `${n}${p.truncated ? " (the first ones of a streamed plan)" : ""}`;
      frames.textContent = p.text || "(nothing is sent)";
      const details = element.querySelector(".flow-plan");
      details.hidden = false;
      details.open = true;
      say(`Dry run of ${request.op}: nothing was sent${p.ask ? "; running it asks first" : ""}.`, "ok");
      return p;
    } catch (e) {
      effect.textContent = confirm.textContent = steps.textContent = "–";
      frames.textContent = "";
      say(`Dry run refused${e?.kind ? ` (${e.kind})` : ""}: ${e?.message ?? e}`, "error");
      return null;
    }
  }

  /**
   * The dry run, then the run (the confirmation dialog first when the plan asks); the
   * report drawn. Resolves to the report, or null (refused, cancelled or failed: said).
   */
  async function run(request, { long = false } = {}) {
    const plan = await dryRun(request);
    if (!plan) return null;
    say(`Running ${request.op}…`);
    progress.hidden = !long;
    progress.value = 0;
    try {
      const rep = await studio.confirmAndRun(request, {
        long,
        onProgress: (p) => {
          if (p.total) progress.max = p.total;
          progress.value = p.done ?? 0;
        },
        onStart: (hd) => {
          handle = hd;
          stopBtn.hidden = false;
        },
      });
      if (rep == null) {
        say("Cancelled: nothing was sent.");
        return null;
      }
      show(rep, request);
      const problem = reportProblem(rep);
      if (problem) say(`${request.op} ran; ${clip(problem)}`, "error");
      else say(`${request.op} ran.`, "ok");
      return rep;
    } catch (e) {
      say(`${request.op} failed: ${describeError(e)}`, "error");
      return null;
    } finally {
      progress.hidden = true;
      stopBtn.hidden = true;
      handle = null;
    }
  }

  function show(rep, request) {
    const drawn = render?.(rep, request);
    if (drawn === undefined) {
      report.replaceChildren(h("pre", { class: "report", tabindex: 0 }, JSON.stringify(rep, null, 2)));
    } else {
      report.replaceChildren(...[].concat(drawn ?? []).filter((c) => c != null));
    }
  }

  return { element, dryRun, run, say, show, stop: () => handle?.stop() };
}

/**
 * The two buttons of a form: "Dry run" and the run itself (`label`), both building the
 * request with `build()` (which throws an Error naming the bad field: shown, nothing sent).
 * `onReport(report, request)` gets a report that came back. Returns the row element.
 */
export function flowButtons(studio, flow, { label, build, long = false, onReport, danger = false, name, changes = true }) {
  const dry = h("button", { type: "button", class: "secondary" }, "Dry run");
  dry.setAttribute("aria-label", `Dry run: ${name ?? label}`);
  const go = h("button", { type: "button", class: danger ? "danger" : "" }, label);
  if (name) go.setAttribute("aria-label", name);
  const built = () => {
    try {
      return build();
    } catch (e) {
      flow.say(describeError(e), "error");
      return null;
    }
  };
  dry.addEventListener("click", () => {
    const r = built();
    if (r) flow.dryRun(r);
  });
  go.addEventListener("click", async () => {
    const r = built();
    if (!r) return;
    go.disabled = true;
    try {
      const rep = await flow.run(r, { long });
      if (rep) onReport?.(rep, r);
    } finally {
      go.disabled = changes && studio.state.readOnly;
    }
  });
  if (changes) writes(studio, go);
  return h("div", { class: "row flow-buttons" }, dry, go);
}

/** A number from a form field, bounded: an Error naming the field, the value and the range otherwise. */
export function boundedNumber(input, label, min, max, { integer = true } = {}) {
  const text = String(input.value).trim();
  const v = Number(text);
  if (text === "" || !Number.isFinite(v) || (integer && !Number.isInteger(v)) || v < min || v > max) {
    throw new Error(`${label}: ${text === "" ? "(empty)" : text} is not ${integer ? "a whole number" : "a number"} in ${min}..=${max}`);
  }
  return v;
}

/** A labelled control in a `.field` box (the label's text is the control's accessible name). */
export function labelled(text, control) {
  if (!control.id) control.id = `flow-${Math.random().toString(36).slice(2, 9)}`;
  return h("div", { class: "field" }, h("label", { for: control.id }, text), control);
}

/** A report's rows as a table: `columns` are [header, key or (row) => text]. */
export function reportTable(caption, columns, rows) {
  return h("div", { class: "table-wrap" },
    h("table", {},
      h("caption", {}, caption),
      h("thead", {}, h("tr", {}, columns.map(([c]) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, rows.map((r) => h("tr", { class: r?.kind ? "failed" : "" },
        columns.map(([, f]) => h("td", {}, cell(typeof f === "function" ? f(r) : r?.[f]))))))));
}

function cell(v) {
  if (v === null || v === undefined) return "—";
  if (v instanceof Node) return v;
  if (typeof v === "number") return Number.isInteger(v) ? String(v) : v.toFixed(3).replace(/\.?0+$/, "");
  if (typeof v === "object") return JSON.stringify(v);
  return String(v);
}
