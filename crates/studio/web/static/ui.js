// Small DOM helpers shared by the panels (optional: a panel may use core.js alone).

import { el, describeError } from "./core.js";

export { el };

let uid = 0;
/** A fresh element id with a readable prefix. */
export function newId(prefix) {
  uid += 1;
  return `${prefix}-${uid}`;
}

/** A `<label for>` and its control in one `.field` box; `hint` adds a small note under it. */
export function field(labelText, control, hint) {
  if (!control.id) control.id = newId("f");
  return el("div", { className: "field" }, [
    el("label", { htmlFor: control.id }, labelText),
    control,
    hint ? el("small", { className: "hint" }, hint) : null,
  ]);
}

/** A number input. */
export function numberInput({ value, min, max, step = 1, width = 6 } = {}) {
  return el("input", { type: "number", min, max, step, value, size: width, className: "num" });
}

/** A select of `[value, text]` pairs (or plain values). */
export function select(options, value) {
  const s = el("select", {});
  for (const o of options) {
    const [v, t] = Array.isArray(o) ? o : [o, o];
    s.append(el("option", { value: String(v) }, t));
  }
  if (value !== undefined) s.value = String(value);
  return s;
}

/** How a device is called on the page: "servo 3" / "joint 1", with its robot name when it has one. */
export function deviceLabel(family, d) {
  const what = family === "wck" ? "Servo" : "Joint";
  return `${what} ${d.id}${d.name ? ` · ${d.name}` : ""}`;
}

/**
 * A device picker of one family or both: a `<select>` whose options follow `studio.ids()`
 * (renewed after a Bus scan). When nothing is known, an ID can still be typed.
 * Returns {element, get(): {family, bus, id} | null, onChange(fn)}.
 */
export function devicePicker(studio, { families = ["wck", "whj"], label = "Device", initial } = {}) {
  const sel = el("select", { className: "device-select" });
  const listeners = [];
  const fill = () => {
    const old = sel.value;
    sel.replaceChildren();
    for (const family of families) {
      const buses = studio.buses(family);
      const devices = studio.ids(family);
      const group = el("optgroup", { label: family === "wck" ? "wCK servos (UART)" : "WHJ joints (CAN FD)" });
      for (const d of devices) {
        const multi = buses.length > 1 ? ` (${d.bus})` : "";
        group.append(el("option", { value: `${family}|${d.bus}|${d.id}` }, `${deviceLabel(family, d)}${multi}`));
      }
      if (!devices.length) {
        // Nothing known yet (hardware without a robot file, no scan): offer the usual IDs.
        const ids = family === "wck" ? range(0, 30) : range(1, 30);
        for (const bus of buses) {
          for (const id of ids) {
            group.append(
              el("option", { value: `${family}|${bus}|${id}` }, `${deviceLabel(family, { id })}${buses.length > 1 ? ` (${bus})` : ""}`),
            );
          }
        }
      }
      if (group.children.length) sel.append(group);
    }
    if (old && [...sel.options].some((o) => o.value === old)) sel.value = old;
    else if (initial && [...sel.options].some((o) => o.value === initial)) sel.value = initial;
  };
  fill();
  for (const f of families) studio.on("devices", (m) => m.family === f && (fill(), fire()));
  const get = () => {
    if (!sel.value) return null;
    const [family, bus, id] = sel.value.split("|");
    return { family, bus, id: Number(id) };
  };
  let last = sel.value;
  const fire = () => {
    if (sel.value === last) return;
    last = sel.value;
    for (const fn of listeners) fn(get());
  };
  sel.addEventListener("change", fire);
  return {
    element: field(label, sel),
    select: sel,
    get,
    set(value) {
      sel.value = value;
      fire();
    },
    onChange: (fn) => listeners.push(fn),
  };
}

export function range(a, b) {
  const out = [];
  for (let i = a; i <= b; i++) out.push(i);
  return out;
}

/** A number shown with its unit (`—` when missing). */
export function fmt(v, digits = 1) {
  if (v === null || v === undefined || Number.isNaN(v)) return "—";
  if (typeof v === "number") return Number.isInteger(v) && digits >= 0 ? String(v) : v.toFixed(digits);
  return String(v);
}

/**
 * An action: a button that runs `request()` through `studio.confirmAndRun` (a dialog when
 * it writes EEPROM / flash), and beside it a "Preview" button that shows its dry run.
 * `onReport(report)` is called with the report; errors become toasts.
 */
export function action(studio, { label, request, onReport, className = "", name, disabled, long = false }) {
  const b = el("button", { type: "button", className }, label);
  if (name) b.setAttribute("aria-label", name);
  b.addEventListener("click", async () => {
    let req;
    try {
      req = request();
    } catch (e) {
      studio.toast(e);
      return;
    }
    b.disabled = true;
    b.setAttribute("aria-busy", "true");
    try {
      const report = await studio.confirmAndRun(req, { long });
      if (report) {
        onReport?.(report);
        const problem = reportProblem(report);
        if (problem) studio.toast(`${label}: ${problem}`, "error");
        else studio.toast(`${name ?? label}: done`, "ok");
      }
    } catch (e) {
      studio.toast(e);
    } finally {
      b.removeAttribute("aria-busy");
      b.disabled = disabled?.() ?? studio.state.readOnly;
    }
  });
  const p = el(
    "button",
    { type: "button", className: "preview-btn", title: "Show the packets or frames it would send" },
    "Preview",
  );
  p.setAttribute("aria-label", `Preview ${name ?? label}`);
  p.addEventListener("click", () => {
    try {
      studio.preview(request());
    } catch (e) {
      studio.toast(e);
    }
  });
  writes(studio, b);
  return { element: el("span", { className: "action" }, [b, p]), button: b, preview: p };
}

/**
 * Mark a button as one that changes a device: disabled on a read-only studio, with a
 * tooltip that says why. Returns the button.
 */
export function writes(studio, button) {
  if (studio.state.readOnly) {
    button.disabled = true;
    button.title = "read-only studio: nothing that changes a device is served";
  }
  return button;
}

/** The failure of a report, if a device in it failed: "kind: error" of the first failing row. */
export function reportProblem(report) {
  if (!report) return null;
  const rows = report.results ?? [];
  const bad = rows.find((r) => r && r.kind);
  if (bad) return `${bad.kind}: ${bad.error ?? "failed"}`;
  if (report.failed) return `${report.failed}: ${report.error ?? "failed"}`;
  return null;
}

/** A table of rows; `columns` are [header, (row) => cell content, className?]. */
export function table(columns, rows, { caption, rowClass } = {}) {
  const t = el("table", {});
  if (caption) t.append(el("caption", {}, caption));
  t.append(el("thead", {}, el("tr", {}, columns.map(([h]) => el("th", { scope: "col" }, h)))));
  const body = el("tbody", {});
  for (const r of rows) {
    const tr = el("tr", { className: rowClass?.(r) ?? "" });
    for (const [, f, cls] of columns) {
      const v = f(r);
      tr.append(el("td", { className: cls ?? "" }, v instanceof Node ? v : fmt(v, 2)));
    }
    body.append(tr);
  }
  t.append(body);
  return t;
}

/** Keyed fields of a result row, as "key value, key value" text (for verifications). */
export function rowText(row, skip = ["id"]) {
  return Object.entries(row)
    .filter(([k]) => !skip.includes(k))
    .map(([k, v]) => `${k.replaceAll("_", " ")}: ${typeof v === "object" ? JSON.stringify(v) : v}`)
    .join(", ");
}

export { describeError };

/** An element from a tag, attributes (`class`, `onclick`, ARIA and others) and children:
 * the compact form the Waveform, Program, Poses, Preview and Capture panels use. */
export function h(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v == null || v === false) continue;
    if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    else if (k === "class") e.className = v;
    else e.setAttribute(k, v === true ? "" : String(v));
  }
  e.append(...children.flat().filter((c) => c != null));
  return e;
}

/** Loads a panel's own stylesheet (panels/NAME.css) once. */
export function panelStyles(name) {
  const href = new URL(`./panels/${name}.css`, import.meta.url).pathname;
  if (!document.querySelector(`link[href="${href}"]`)) {
    const link = document.createElement("link");
    link.rel = "stylesheet";
    link.href = href;
    document.head.append(link);
  }
}

/** `line:column: message` inside a library error (`program 2:6: position 300 …`). */
export function errorPosition(message) {
  const m = /(\d+):(\d+):\s*([\s\S]*)$/.exec(message ?? "");
  return m ? { line: Number(m[1]), column: Number(m[2]), message: m[3] } : null;
}
