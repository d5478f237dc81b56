// Backup: a device's settings to a file (downloaded from the browser), a file (uploaded) or
// another device compared with a device, and a file (or the factory settings) restored into
// a device. Every step is one catalogue request through the flow (its dry run, the EEPROM /
// flash confirmation, the run, the report): `wck.backup` / `whj.backup`, `wck.diff` /
// `whj.diff`, `wck.restore` / `whj.restore`. Copying one device into another is a backup
// of the first, then a restore of that file into the second.

import { h, devicePicker, describeError } from "../ui.js";
import { createFlow, flowButtons, labelled, reportTable } from "./flow.js";

/** The largest settings file read from the disk, bytes (the library bounds it too). */
const MAX_FILE = 256 * 1024;

export default {
  id: "backup",
  title: "Backup",
  mount(root, studio) {
    const families = ["wck", "whj"].filter((f) => studio.buses(f).length);
    const picker = devicePicker(studio, { families, label: "Device" });
    picker.select.setAttribute("aria-label", "Backup device");
    const other = devicePicker(studio, { families, label: "Other device" });
    other.select.setAttribute("aria-label", "Other device");
    const withSel = h("select", {},
      h("option", { value: "file" }, "the settings file"),
      h("option", { value: "other" }, "another device"),
      h("option", { value: "factory" }, "the factory settings (wCK)"));
    withSel.setAttribute("aria-label", "Compare with");
    const fileInput = h("input", { type: "file", accept: ".json,application/json" });
    fileInput.setAttribute("aria-label", "Upload a settings file");
    const fileState = h("p", { class: "hint", "aria-live": "polite", "data-field": "file" }, "No settings file yet: back up a device or upload a file.");
    withSel.addEventListener("change", () => (other.element.hidden = withSel.value !== "other"));
    other.element.hidden = true;
    const download = h("button", { type: "button", class: "secondary", disabled: true }, "Download the file");
    const flow = createFlow(studio, { name: "Backup", render });
    /** The settings file in hand: {family, text, name}. */
    let file = null;

    const device = () => {
      const d = picker.get();
      if (!d) throw new Error("pick a device");
      return d;
    };
    const target = (d) => (d.family === "wck" ? { id: d.id } : { joint: d.id });
    const fileFor = (d) => {
      if (!file) throw new Error("no settings file: back up a device or upload a file first");
      if (file.family !== d.family) throw new Error(`the settings file is of a ${file.family === "wck" ? "wCK servo" : "WHJ joint"}; ${noun(d)} is not`);
      return file.text;
    };

    function setFile(family, text, name) {
      file = { family, text, name };
      fileState.textContent = `Settings file: ${name} (${family === "wck" ? "wCK servo" : "WHJ joint"}, ${text.length} bytes).`;
      download.disabled = false;
    }

    download.addEventListener("click", () => {
      if (!file) return;
      const a = h("a", { href: URL.createObjectURL(new Blob([file.text], { type: "application/json" })), download: file.name });
      document.body.append(a);
      a.click();
      setTimeout(() => {
        URL.revokeObjectURL(a.href);
        a.remove();
      }, 0);
    });

    fileInput.addEventListener("change", async () => {
      const f = fileInput.files?.[0];
      if (!f) return;
      if (f.size > MAX_FILE) {
        flow.say(`${f.name}: ${f.size} bytes is more than a settings file (at most ${MAX_FILE}); not loaded.`, "error");
        return;
      }
      try {
        const text = await f.text();
        const json = JSON.parse(text);
        // The family is the file's own word (`format`); the device checks the rest.
        const family = String(json.format ?? "").includes("wck") ? "wck" : "whj";
        setFile(family, text, f.name);
        flow.say(`Loaded ${f.name}; diff or restore checks it against the device.`, "ok");
      } catch (e) {
        flow.say(`${f.name} is not a settings file: ${describeError(e)}`, "error");
      } finally {
        fileInput.value = "";
      }
    });

    const backupRow = flowButtons(studio, flow, {
      label: "Back up",
      name: "Back up the device",
      changes: false,
      build: () => {
        const d = device();
        return { op: `${d.family}.backup`, bus: d.bus, ...target(d) };
      },
      onReport: (rep, req) => {
        if (rep.failed || !rep.summary) return;
        const family = req.op.split(".")[0];
        const id = req.id ?? req.joint;
        setFile(family, JSON.stringify(rep.summary, null, 2), `${family === "wck" ? "servo" : "joint"}-${id}-${req.bus}.settings.json`);
      },
    });

    function comparison(d) {
      const w = withSel.value;
      if (w === "factory") {
        if (d.family !== "wck") throw new Error("WHJ joints have no factory settings: compare with a file (whj.defaults makes one) or another joint");
        return { factory: true };
      }
      if (w === "other") {
        const o = other.get();
        if (!o) throw new Error("pick the other device");
        if (o.family !== d.family || o.bus !== d.bus) throw new Error(`the other device must be on ${d.bus} with ${noun(d)} (it is ${noun(o)} on ${o.bus})`);
        if (o.id === d.id) throw new Error(`compare ${noun(d)} with another device, not itself`);
        return { other: o.id };
      }
      return { settings: fileFor(d) };
    }

    const diffRow = flowButtons(studio, flow, {
      label: "Diff",
      name: "Diff the device",
      changes: false,
      build: () => {
        const d = device();
        return { op: `${d.family}.diff`, bus: d.bus, ...target(d), ...comparison(d) };
      },
    });
    const restoreRow = flowButtons(studio, flow, {
      label: "Restore",
      name: "Restore into the device",
      danger: true,
      build: () => {
        const d = device();
        const c = comparison(d);
        if (c.other !== undefined) throw new Error("to restore another device's settings, use Copy: it backs the other device up, then restores that file");
        return { op: `${d.family}.restore`, bus: d.bus, ...target(d), ...c };
      },
    });
    // Another device into this one: its backup (the settings file from then on), then the
    // restore of that file, each through the flow (the restore asks first).
    const copyRow = flowButtons(studio, flow, {
      label: "Copy",
      name: "Copy the other device into the device",
      danger: true,
      build: () => {
        const d = device();
        if (withSel.value !== "other") throw new Error('Copy takes the settings of another device: choose "another device"');
        const o = { ...d, id: comparison(d).other };
        return { op: `${o.family}.backup`, bus: o.bus, ...target(o) };
      },
      onReport: async (rep, req) => {
        if (rep.failed || !rep.summary) return;
        const d = device();
        const family = req.op.split(".")[0];
        const id = req.id ?? req.joint;
        setFile(family, JSON.stringify(rep.summary, null, 2), `${family === "wck" ? "servo" : "joint"}-${id}-${req.bus}.settings.json`);
        await flow.run({ op: `${d.family}.restore`, bus: d.bus, ...target(d), settings: file.text });
      },
    });
    const syncCopy = () => {
      copyRow.hidden = withSel.value !== "other";
      restoreRow.hidden = withSel.value === "other";
    };
    withSel.addEventListener("change", syncCopy);
    syncCopy();

    root.append(
      h("h2", {}, "Backup"),
      h("p", { class: "lead" }, "Back a device's settings up to a file, compare a device with a file, another device or the ",
        "factory settings, and restore a file into a device (the same device or another of its family). Each step shows its ",
        "dry run; a restore writes EEPROM or flash and asks first."),
      h("section", { class: "card", "aria-label": "Backup, diff and restore" },
        h("div", { class: "row" }, picker.element),
        h("h3", {}, "1. Back up"),
        backupRow,
        h("h3", {}, "The settings file"),
        fileState,
        h("div", { class: "row" }, download, labelled("Upload a file", fileInput)),
        h("h3", {}, "2. Compare and restore"),
        h("div", { class: "row" }, labelled("Compare or restore with", withSel), other.element),
        diffRow,
        restoreRow,
        copyRow,
        flow.element));
  },
};

function noun(d) {
  return `${d.family === "wck" ? "servo" : "joint"} ${d.id}`;
}

/** A report drawn for the user: the backup's settings, the differences, the writes. */
function render(rep, req) {
  const [, what] = req.op.split(".");
  if (rep.failed) return h("p", { class: "fail" }, `${rep.failed}: ${rep.error ?? "failed"}`);
  if (what === "backup") {
    const s = rep.summary ?? {};
    if (req.op === "wck.backup") {
      return reportTable(`Servo ${req.id}'s settings`, [["Setting", 0], ["Value", 1]],
        ["p_gain", "d_gain", "i_gain", "speed", "accel", "overload", "lower", "upper"].map((k) => [k, s[k]]));
    }
    return reportTable(`Joint ${req.joint}'s settings (${s.model}, firmware ${s.firmware})`,
      [["Register", "register"], ["Addr", "addr"], ["Raw", "raw"], ["Value", "value"], ["Unit", "unit"]], s.settings ?? []);
  }
  if (what === "diff") {
    const rows = rep.results ?? [];
    const head = h("p", { class: rows.length ? "" : "diff-same", "data-field": "differ" },
      rows.length ? `${rows.length} ${rows.length === 1 ? "setting differs" : "settings differ"} from ${rep.summary?.with ?? "the other"}.` : `No difference from ${rep.summary?.with ?? "the other"}.`);
    if (!rows.length) return head;
    const cols = req.op === "wck.diff"
      ? [["Group", "setting"], ["This device", "a"], [rep.summary?.with ?? "Other", "b"]]
      : [["Register", "register"], ["Addr", "addr"], ["This joint", (r) => r.a_value ?? r.a], [rep.summary?.with ?? "Other", (r) => r.b_value ?? r.b], ["Unit", "unit"]];
    return [head, reportTable("Differences", cols, rows)];
  }
  if (what === "restore") {
    const rows = rep.results ?? [];
    const head = h("p", { "data-field": "written" }, `Restored: ${rep.summary?.written ?? rows.length} written${rep.summary?.saved !== undefined ? `, saved: ${rep.summary.saved}` : ""}${rep.summary?.differ_after !== undefined ? `, differing after: ${rep.summary.differ_after}` : ""}.`);
    if (!rows.length) return head;
    const cols = req.op === "wck.restore"
      ? [["Group", "setting"], ["From", "from"], ["To", "to"]]
      : [["Register", "register"], ["From", "from"], ["To", "to"], ["Action", "action"]];
    return [head, reportTable("Writes", cols, rows)];
  }
  return undefined;
}
