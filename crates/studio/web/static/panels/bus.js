// Bus: find the devices on each bus (scan), and change a device's ID or bit rate. A scan
// row opens its device's whole settings table in the Settings panel.

import { el, field, select, numberInput, table, fmt, rowText, describeError, writes, panelStyles } from "../ui.js";

const WCK_RATES = [4800, 9600, 38400, 57600, 115200, 230400, 460800, 921600];

export default {
  id: "bus",
  title: "Bus",
  mount(root, studio) {
    panelStyles("flow");
    root.append(
      el("h2", {}, "Bus"),
      el("p", { className: "lead" }, "Scan a bus to find its devices; change a device's ID or bit rate (written to its EEPROM / flash after a confirmation)."),
    );
    const grid = el("div", { className: "columns" });
    root.append(grid);
    for (const family of ["wck", "whj"]) {
      if (studio.buses(family).length) grid.append(familySection(studio, family));
    }
    if (!grid.children.length) root.append(el("p", {}, "This studio has no bus."));
    root.append(portsSection(studio));
  },
};

// The serial ports of the machine the studio runs on, as its OS knows them (the
// catalogue's read-only `host.ports`: what `robobus ports` prints): each with the adapter
// robobus recognises, what it is for, and this OS's latency-timer advice.
function portsSection(studio) {
  const list = el("button", { type: "button", className: "secondary" }, "List serial ports");
  const summary = el("p", { className: "summary", "aria-live": "polite" }, "Not listed yet.");
  const results = el("div", { className: "results" });
  const usb = (r) =>
    r.vid === null || r.vid === undefined
      ? "—"
      : `${r.vid.toString(16).padStart(4, "0")}:${r.pid.toString(16).padStart(4, "0")}`;
  const strings = (r) => [r.manufacturer, r.product, r.serial_number && `serial ${r.serial_number}`].filter(Boolean).join(", ") || "—";
  const latency = (r) => {
    const parts = [];
    if (r.latency_timer_ms !== null && r.latency_timer_ms !== undefined) parts.push(`${r.latency_timer_ms} ms`);
    if (r.latency_advice) parts.push(r.latency_advice);
    return parts.join(": ") || "—";
  };
  list.addEventListener("click", async () => {
    list.disabled = true;
    summary.textContent = "Listing…";
    try {
      const report = await studio.run({ op: "host.ports" });
      const rows = report.results ?? [];
      const os = report.summary?.os ?? "this machine";
      summary.textContent = rows.length
        ? `${rows.length} serial port${rows.length === 1 ? "" : "s"} on ${os}.`
        : `No serial port found; ${report.summary?.where ?? ""}`;
      results.replaceChildren(
        rows.length
          ? el(
              "div",
              { className: "table-wrap" },
              table(
                [
                  ["Port", (r) => r.id, "mono"],
                  ["Kind", (r) => r.kind],
                  ["USB", usb, "mono"],
                  ["Device", strings],
                  ["Adapter", (r) => r.adapter ?? "—"],
                  ["Use", (r) => r.use_for ?? "—"],
                  ["Latency timer", latency],
                ],
                rows,
                { caption: "Serial ports of this machine" },
              ),
            )
          : "",
      );
    } catch (e) {
      summary.textContent = `Failed: ${describeError(e)}`;
      studio.toast(e);
    } finally {
      list.disabled = false;
    }
  });
  return el("section", { className: "card", "aria-label": "Serial ports" }, [
    el("h3", {}, "Serial ports of this machine"),
    el("p", { className: "hint" }, "What the OS knows of each port (COM ports, /dev/cu.*, /dev/ttyUSB*): the adapter robobus recognises, the option that uses it, and the latency-timer advice. Nothing is opened."),
    el("div", { className: "row" }, [list]),
    summary,
    results,
  ]);
}

function familySection(studio, family) {
  const wck = family === "wck";
  const noun = wck ? "servo" : "joint";
  const title = wck ? "wCK servos (UART)" : "WHJ joints (CAN FD)";
  const buses = studio.buses(family);
  const busSel = select(buses);
  const ids = el("input", { type: "text", value: wck ? "0-30" : "1-30", size: 8, spellcheck: false });
  const allRates = el("input", { type: "checkbox" });
  const scan = el("button", { type: "button" }, `Scan ${wck ? "wCK" : "WHJ"} bus`);
  const stop = el("button", { type: "button", className: "secondary", disabled: true }, "Stop scan");
  stop.setAttribute("aria-label", `Stop ${wck ? "wCK" : "WHJ"} scan`);
  const bar = el("progress", { max: 1, value: 0 });
  bar.setAttribute("aria-label", `${wck ? "wCK" : "WHJ"} scan progress`);
  const barText = el("span", { className: "progress-text" }, "");
  const summary = el("p", { className: "summary", "aria-live": "polite" }, "Not scanned yet.");
  const results = el("div", { className: "results" });
  const editor = el("div", { className: "editor", hidden: true });
  let handle = null;
  let lastReport = null;

  scan.addEventListener("click", async () => {
    const request = { op: wck ? "wck.scan" : "whj.scan", bus: busSel.value };
    request[wck ? "ids" : "joints"] = ids.value.trim() || (wck ? "0-30" : "1-30");
    if (wck && allRates.checked) request.all_bauds = true;
    scan.disabled = true;
    stop.disabled = false;
    bar.removeAttribute("value"); // indeterminate until the first progress
    barText.textContent = "starting…";
    summary.textContent = "";
    editor.hidden = true;
    handle = studio.runLong(request, (p) => {
      if (p.total) {
        bar.max = p.total;
        bar.value = p.done;
      } else {
        bar.removeAttribute("value");
      }
      barText.textContent = `${p.stage} ${p.done}${p.total ? `/${p.total}` : ""}${p.note ? ` · ${p.note}` : ""}`;
    });
    try {
      const report = await handle.promise;
      lastReport = report;
      const stopped = report.failed === "interrupted";
      bar.max = 1;
      bar.value = stopped ? 0 : 1;
      barText.textContent = stopped ? "stopped" : "done";
      show(report);
      if (stopped) {
        summary.textContent = `Stopped: ${report.error ?? "the scan was stopped"}. ${summary.textContent}`;
        studio.toast("Scan stopped.");
      } else if (report.failed) {
        studio.toast(`Scan: ${report.failed}: ${report.error ?? "failed"}`, "error");
      }
    } catch (e) {
      bar.max = 1;
      bar.value = 0;
      barText.textContent = e.kind === "interrupted" ? "stopped" : "failed";
      if (e.kind === "interrupted") studio.toast("Scan stopped.");
      else studio.toast(e);
    } finally {
      handle = null;
      scan.disabled = false;
      stop.disabled = true;
    }
  });
  stop.addEventListener("click", () => handle?.stop());

  function duplicateIds(report) {
    const out = new Set();
    for (const d of report.summary?.duplicates ?? []) {
      if (typeof d === "number") out.add(d);
      else if (d && typeof d === "object") out.add(d.id ?? d.node_id ?? d.joint);
    }
    return out;
  }

  function show(report) {
    const rows = (report.results ?? []).filter((r) => !r.kind);
    const dups = duplicateIds(report);
    const rates = report.summary?.bauds_tried;
    summary.textContent =
      `Found ${rows.length} ${noun}${rows.length === 1 ? "" : "s"} on ${report.bus}` +
      (rates ? ` (rates tried: ${rates.join(", ")} bit/s)` : "") +
      (dups.size ? `; duplicate IDs: ${[...dups].join(", ")}` : "") +
      ".";
    studio.setDevices(family, report.bus, rows);
    const idCell = (r) => {
      const open = el("button", { type: "button", className: "link", title: `Open the settings of ${noun} ${r.id}`, onclick: () => openDevice(r, report.bus) }, String(r.id));
      open.setAttribute("aria-label", `Open ${noun} ${r.id}`);
      return dups.has(r.id) ? el("span", {}, [open, " ", el("strong", { className: "fail" }, "duplicate ID")]) : open;
    };
    const cols = wck
      ? [
          ["ID", idCell],
          ["Bit rate", (r) => (r.baud ? `${r.baud} bit/s` : "—"), "nowrap"],
          ["Position", (r) => `${r.position} steps (${fmt(r.degrees, 1)}°)`, "nowrap"],
          ["Change", (r) => changeButtons(r, report.bus)],
        ]
      : [
          ["ID", idCell],
          ["Model", (r) => r.model ?? "—"],
          ["Firmware", (r) => r.firmware ?? "—"],
          ["Reduction", (r) => (r.reduction ? `${r.reduction}:1` : "—")],
          ["Unique ID", (r) => r.unique_id ?? "—", "mono"],
          ["Change", (r) => changeButtons(r, report.bus)],
        ];
    results.replaceChildren(
      rows.length
        ? el("div", { className: "table-wrap" }, [
            el("p", { className: "hint" }, `Click a ${noun} (its row or its ID) to open its whole settings table in Settings.`),
            openOnClick(table(cols, rows, { caption: `${title} found on ${report.bus}`, rowClass: (r) => (dups.has(r.id) ? "dup scan-row" : "scan-row") }), rows, report.bus),
          ])
        : el("p", {}, `No ${noun} answered.`),
    );
  }

  /** Open a found device in the Settings panel: its whole settings table, read at once. */
  function openDevice(r, bus) {
    studio.openSettings = { family, bus, id: r.id };
    studio.showPanel?.("settings");
  }

  /** A click anywhere on a row (but its buttons) opens its device. */
  function openOnClick(t, rows, bus) {
    [...t.tBodies[0].rows].forEach((tr, i) => {
      tr.addEventListener("click", (e) => {
        if (!e.target.closest("button, input, select, a")) openDevice(rows[i], bus);
      });
    });
    return t;
  }

  function changeButtons(r, bus) {
    const setId = el("button", { type: "button", className: "small secondary", onclick: () => edit("id", r, bus) }, "Set ID");
    setId.setAttribute("aria-label", `Set ID of ${noun} ${r.id}`);
    const out = el("span", { className: "row-actions" }, [writes(studio, setId)]);
    if (wck) {
      const setRate = el("button", { type: "button", className: "small secondary", onclick: () => edit("rate", r, bus) }, "Set bit rate");
      setRate.setAttribute("aria-label", `Set bit rate of ${noun} ${r.id}`);
      out.append(writes(studio, setRate));
    }
    return out;
  }

  function edit(what, r, bus) {
    const verify = el("p", { className: "verify", "aria-live": "polite" });
    let input;
    let write;
    if (what === "id") {
      input = numberInput({ value: r.id, min: wck ? 0 : 1, max: wck ? 30 : 30 });
      write = el("button", { type: "button", className: "danger" }, "Write new ID");
    } else {
      input = select(WCK_RATES.map((b) => [b, `${b} bit/s`]), r.baud ?? 115200);
      write = el("button", { type: "button", className: "danger" }, "Write new bit rate");
    }
    const cancel = el("button", { type: "button", className: "secondary", onclick: () => (editor.hidden = true) }, "Close");
    const request = () => {
      if (what === "rate") return { op: "wck.set-baud", bus, id: r.id, rate: Number(input.value) };
      const n = Number(input.value);
      return wck ? { op: "wck.set-id", bus, id: r.id, new_id: n } : { op: "whj.set-id", bus, joint: r.id, new_id: n };
    };
    const preview = el("button", { type: "button", className: "preview-btn", onclick: () => studio.preview(request()) }, "Preview");
    preview.setAttribute("aria-label", `Preview ${what === "id" ? "set ID" : "set bit rate"}`);
    write.addEventListener("click", async () => {
      write.disabled = true;
      verify.textContent = "";
      try {
        const report = await studio.confirmAndRun(request());
        if (!report) {
          verify.textContent = "Cancelled: nothing was written.";
          return;
        }
        verify.textContent = verification(what, r, report);
        verify.className = `verify ${report.failed ? "fail" : "ok"}`;
        const row = report.results?.[0];
        if (!row?.kind && lastReport && wck) {
          // Show the device under its new ID / rate without a rescan.
          const old = lastReport.results.find((x) => x.id === r.id);
          if (old && what === "id" && row?.new_id !== undefined) old.id = row.new_id;
          if (old && what === "rate" && row?.baud !== undefined) old.baud = row.baud;
          show(lastReport);
          editor.hidden = false;
        }
      } catch (e) {
        verify.textContent = `Failed: ${describeError(e)}`;
        verify.className = "verify fail";
        studio.toast(e);
      } finally {
        write.disabled = false;
      }
    });
    const label = what === "id" ? `New ID for ${noun} ${r.id}` : `New bit rate for ${noun} ${r.id}`;
    editor.replaceChildren(
      el("h4", {}, what === "id" ? `Set the ID of ${noun} ${r.id}` : `Set the bit rate of ${noun} ${r.id}`),
      el("div", { className: "row" }, [field(label, input), write, preview, cancel]),
      el("p", { className: "hint" }, what === "id"
        ? wck ? "Written to the servo's EEPROM; it answers at the new ID at once." : "Written and saved to flash; the joint answers at the new ID after a power cycle."
        : "Written to the servo's EEPROM; it answers only at the new rate from then on (scan with every rate to find it)."),
      verify,
    );
    editor.hidden = false;
    input.focus();
  }

  function verification(what, r, report) {
    const row = report.results?.[0];
    if (!row) return "No result.";
    if (row.kind) return `Failed: ${row.kind}: ${row.error}`;
    if (what === "rate") return `Verified: ${noun} ${row.id} answers at ${row.baud} bit/s.`;
    if (wck) return `Verified: the servo answers at ID ${row.new_id}.`;
    const parts = [`Joint ${row.id}: ID ${row.new_id} written`];
    if (row.read_back !== undefined) parts.push(`read back ${row.read_back}${row.read_back === row.new_id ? " (verified)" : " (MISMATCH)"}`);
    if (row.saved !== undefined) parts.push(row.saved ? "saved to flash" : "not saved");
    let text = parts.join(", ") + ".";
    if (row.note) text += ` Note: ${row.note}.`;
    if (row.answered_at !== undefined) text += ` It answers at ID ${row.answered_at} until then.`;
    const rest = rowText(row, ["id", "new_id", "read_back", "saved", "note", "answered_at"]);
    return rest ? `${text} (${rest})` : text;
  }

  const controls = [field("Bus", busSel), field(wck ? "Servo IDs" : "Joint IDs", ids)];
  if (wck) {
    allRates.id = `${family}-all-rates`;
    controls.push(
      el("div", { className: "field check" }, [allRates, el("label", { htmlFor: allRates.id }, "Try every bit rate")]),
    );
  }
  if (buses.length < 2) controls[0].hidden = true;
  return el("section", { className: "card", "aria-label": title }, [
    el("h3", {}, title),
    el("div", { className: "row" }, [...controls, scan, stop]),
    el("div", { className: "progress" }, [bar, barText]),
    summary,
    results,
    editor,
  ]);
}
