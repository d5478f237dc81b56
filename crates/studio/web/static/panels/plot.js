// Plot: live charts of target against actual position, and of speed and current, of the
// chosen devices over the last 10..60 s. Drag across a chart to zoom (it pauses).
//
// The readings come from the page's history (history.js): every device is recorded from
// the moment the page connects, so ticking a device draws what it did before too. The
// targets are every position target the studio commanded (jogs, moves: the server's
// `target` messages) and the signal a wave asked for (the Waveform panel's).

import uPlot from "../vendor/uplot/uPlot.esm.js";
import { el, field, select, deviceLabel } from "../ui.js";
import { KEEP_S } from "../history.js";

const COLORS = ["#1f5fbf", "#c0392b", "#1e8449", "#7d3c98", "#b9770e", "#117a8b", "#6e2c00", "#c2185b"];
/** The charts are drawn at most this often (ms): the history changes at every sample. */
const DRAW_MS = 100;

const CHARTS = [
  { id: "position", title: "Position", unit: "deg" },
  { id: "speed", title: "Speed", unit: "rpm" },
  { id: "current", title: "Current", unit: "mA" },
];

export default {
  id: "plot",
  title: "Plot",
  mount(root, studio) {
    new PlotPanel(root, studio);
  },
};

class PlotPanel {
  constructor(root, studio) {
    this.root = root;
    this.studio = studio;
    this.history = studio.history;
    this.paused = false;
    this.zoomPaused = false;
    this.devices = []; // [{family, bus, id, key, color, label}]
    this.t = []; // ms since the epoch, ascending
    this.cols = new Map(); // series key -> values (null: no reading, a gap; undefined: another device's row)
    this.charts = new Map(); // chart id -> {u, keys, box}
    this.dirty = false;
    this.drawnAt = 0;

    this.pick = el("fieldset", { className: "devices" }, [el("legend", {}, "Devices to plot")]);
    this.windowSel = select([10, 15, 20, 30, 45, 60].map((s) => [s, `${s} s`]), 20);
    this.whjRate = select([10, 25, 50].map((r) => [r, `${r} Hz`]), this.history.rates.whj);
    this.wckRate = select([5, 10, 20].map((r) => [r, `${r} Hz`]), this.history.rates.wck);
    this.pauseBtn = el("button", { type: "button", onclick: () => this.setPaused(!this.paused) }, "Pause");
    const reset = el("button", { type: "button", className: "secondary", onclick: () => this.resetZoom() }, "Reset zoom");
    const csv = el("button", { type: "button", className: "secondary", onclick: () => this.exportCsv() }, "Export CSV");
    const png = el("button", { type: "button", className: "secondary", onclick: () => this.exportPng() }, "Export PNG");
    this.status = el("p", { className: "hint", "aria-live": "polite" });
    this.chartBox = el("div", { className: "charts" });
    root.append(
      el("h2", {}, "Plot"),
      el(
        "p",
        { className: "lead" },
        `Target (dashed) against actual, live: the targets of every jog, move and wave the studio starts. Every device is recorded from the moment the page opened (the last ${KEEP_S} s); ticking one chooses what is drawn. Drag across a chart to zoom in; that pauses the view.`,
      ),
      el("div", { className: "row plot-controls" }, [
        field("Window", this.windowSel),
        field("WHJ sample rate", this.whjRate),
        field("wCK sample rate", this.wckRate),
        this.pauseBtn,
        reset,
        csv,
        png,
      ]),
      this.pick,
      this.status,
      this.chartBox,
    );
    this.fillDevices();
    studio.on("devices", () => this.fillDevices());
    this.windowSel.addEventListener("change", () => this.redraw(true));
    this.whjRate.addEventListener("change", () => this.history.setRate("whj", Number(this.whjRate.value)));
    this.wckRate.addEventListener("change", () => this.history.setRate("wck", Number(this.wckRate.value)));
    this.history.onChange(() => {
      this.dirty = true;
    });
    root.addEventListener("studio:show", () => {
      this.resize();
      this.redraw(true);
    });
    this.resizeObs = new ResizeObserver(() => this.resize());
    this.resizeObs.observe(this.chartBox);
    const frame = (now) => {
      if (this.dirty && !this.paused && !this.root.hidden && now - this.drawnAt >= DRAW_MS) {
        this.drawnAt = now;
        this.redraw(false);
      }
      requestAnimationFrame(frame);
    };
    requestAnimationFrame(frame);
    this.restart();
  }

  fillDevices() {
    const checked = new Set([...this.pick.querySelectorAll("input:checked")].map((i) => i.value));
    const first = !this.pick.querySelector("input");
    for (const n of [...this.pick.children]) if (n.tagName !== "LEGEND") n.remove();
    const all = [
      ...this.studio.ids("whj").map((d) => ({ family: "whj", ...d })),
      ...this.studio.ids("wck").map((d) => ({ family: "wck", ...d })),
      // The robot file's joints, in its joint frame: recorded while a robot.play runs.
      ...this.history.robot.map((j) => ({ family: "robot", bus: "robot", id: j.name, joint: j.family })),
    ];
    const multi = { wck: this.studio.buses("wck").length > 1, whj: this.studio.buses("whj").length > 1 };
    all.forEach((d, i) => {
      const value = `${d.family}|${d.bus}|${d.id}`;
      const box = el("input", { type: "checkbox", value, id: `plot-dev-${i}` });
      box.checked = first ? i === 0 : checked.has(value);
      box.addEventListener("change", () => this.restart());
      const text = d.family === "robot" ? `Robot joint ${d.id}` : `${deviceLabel(d.family, d)}${multi[d.family] ? ` (${d.bus})` : ""}`;
      if (d.family === "robot" && !this.pick.querySelector(".robot-note")) {
        this.pick.append(el("p", { className: "hint robot-note" }, "Robot joints, by name in the robot file's joint frame: recorded while a pose or trajectory (robot.play) of this page runs, with its points as their target."));
      }
      this.pick.append(el("span", { className: "check" }, [box, el("label", { htmlFor: box.id }, text)]));
    });
    if (!all.length) this.pick.append(el("p", { className: "hint" }, "No devices known: scan a bus first."));
    if (!first) this.restart();
  }

  chosen() {
    return [...this.pick.querySelectorAll("input:checked")].map((i, n) => {
      const [family, bus, id] = i.value.split("|");
      const d = { family, bus, id: family === "robot" ? id : Number(id) };
      d.key = i.value;
      d.color = COLORS[n % COLORS.length];
      d.label = family === "robot" ? `robot ${id}` : `${family === "wck" ? "servo" : "joint"} ${id}`;
      d.current = family === "whj" || (family === "robot" && this.history.robot.find((j) => j.name === id)?.family === "whj");
      return d;
    });
  }

  /** Rebuild the charts for the chosen devices (the history records them all already). */
  restart() {
    this.devices = this.chosen();
    this.buildCharts();
    this.status.textContent = this.devices.length ? "" : "Choose a device to plot.";
  }

  /** The rows of the chosen devices from the history: their readings' times and their targets' steps, merged. */
  collect() {
    const h = this.history;
    const tmin = Date.now() - KEEP_S * 1000;
    const tmax = Date.now(); // a wave's asked signal is drawn up to now
    const per = new Map();
    const times = new Set();
    for (const d of this.devices) {
      const r = h.readings(d.key, tmin);
      per.set(d.key, r);
      for (const t of r.t) times.add(t);
      for (const t of h.targetTimes(d.key, tmin, tmax)) times.add(t);
    }
    this.t = [...times].sort((a, b) => a - b);
    const index = new Map(this.t.map((t, i) => [t, i]));
    this.cols = new Map();
    const silent = [];
    for (const d of this.devices) {
      const r = per.get(d.key);
      for (const name of ["pos", "speed", "current"]) {
        const col = new Array(this.t.length).fill(undefined);
        r.t.forEach((t, k) => {
          col[index.get(t)] = r[name][k];
        });
        this.cols.set(`${d.key}|${name}`, col);
      }
      this.cols.set(`${d.key}|target`, h.targetAt(d.key, this.t));
      if (h.health.get(d.key)?.silent) silent.push(d);
    }
    if (this.devices.length) {
      this.status.textContent = silent.length
        ? `No reply from ${silent.map((d) => d.label).join(", ")}: no line is drawn while it is silent.`
        : "";
    }
  }

  /** A column of values. */
  column(k) {
    return this.cols.get(k) ?? new Array(this.t.length).fill(null);
  }

  buildCharts() {
    for (const c of this.charts.values()) c.u.destroy();
    this.charts.clear();
    this.chartBox.replaceChildren();
    this.collect();
    const width = this.width();
    for (const spec of CHARTS) {
      const devs = spec.id === "current" ? this.devices.filter((d) => d.current) : this.devices;
      const keys = [];
      const series = [{ label: "time" }];
      for (const d of devs) {
        if (spec.id === "position") {
          keys.push(`${d.key}|pos`, `${d.key}|target`);
          series.push(
            { label: `${d.label} actual`, stroke: d.color, width: 2 },
            { label: `${d.label} target`, stroke: d.color, width: 1.5, dash: [6, 4], spanGaps: true, paths: uPlot.paths.stepped({ align: 1 }) },
          );
        } else {
          keys.push(`${d.key}|${spec.id}`);
          series.push({ label: `${d.label} ${spec.id}`, stroke: d.color, width: 2 });
        }
      }
      const fig = el("figure", { className: "chart" });
      fig.setAttribute("aria-label", `${spec.title} (${spec.unit}) chart`);
      const caption = el("figcaption", {}, `${spec.title} (${spec.unit})`);
      fig.append(caption);
      this.chartBox.append(fig);
      if (!devs.length) {
        fig.append(el("p", { className: "hint" }, spec.id === "current" ? "wCK servos report load, not current: choose a WHJ joint." : "No device chosen."));
        continue;
      }
      const opts = {
        width,
        height: 200,
        series,
        scales: {
          x: { time: true },
          // Flat data (a joint at rest) gets a small range around it, not 0..100.
          y: { range: (u, min, max) => (min === max || min == null ? [(min ?? 0) - 1, (max ?? 0) + 1] : uPlot.rangeNum(min, max, 0.1, true)) },
        },
        axes: [
          {
            label: "time",
            stroke: "#333",
            grid: { stroke: "#e4e7eb" },
            space: 70,
            incrs: [1, 2, 5, 10, 15, 30, 60],
            values: (u, splits) => splits.map(clock),
          },
          { label: `${spec.title} (${spec.unit})`, stroke: "#333", grid: { stroke: "#e4e7eb" }, size: 60 },
        ],
        cursor: { sync: { key: "robobus-plot" }, drag: { x: true, y: false, setScale: false } },
        legend: { live: true },
        hooks: {
          setSelect: [
            (u) => {
              if (u.select.width < 4) return;
              const min = u.posToVal(u.select.left, "x");
              const max = u.posToVal(u.select.left + u.select.width, "x");
              u.setSelect({ left: 0, top: 0, width: 0, height: 0 }, false);
              this.zoomTo(min, max);
            },
          ],
        },
      };
      const defs = series.slice(1).map(({ label, stroke, dash }) => ({ label, stroke, dash }));
      const u = new uPlot(opts, this.data(keys), fig);
      fig.uplot = u; // for the browser tests
      this.charts.set(spec.id, { u, keys, spec, defs });
    }
    this.redraw(true);
  }

  width() {
    return Math.max(320, (this.chartBox.clientWidth || this.root.clientWidth || 800) - 8);
  }

  resize() {
    if (this.root.hidden || !this.chartBox.clientWidth) return;
    const w = this.width();
    for (const c of this.charts.values()) if (Math.abs(c.u.width - w) > 2) c.u.setSize({ width: w, height: 200 });
  }

  /** The window shown when live: its last `window` seconds up to the newest reading. */
  windowRange() {
    const end = this.t.length ? Math.max(this.t[this.t.length - 1], Date.now() - 500) : Date.now();
    return [(end - Number(this.windowSel.value) * 1000) / 1000, end / 1000];
  }

  data(keys) {
    return [this.t.map((t) => t / 1000), ...keys.map((k) => this.column(k))];
  }

  redraw(force) {
    if (this.paused && !force) return;
    this.dirty = false;
    if (!this.paused) this.collect();
    const [min, max] = this.windowRange();
    for (const c of this.charts.values()) {
      c.u.setData(this.data(c.keys), false);
      if (!this.zoomPaused) c.u.setScale("x", { min, max });
    }
  }

  zoomTo(min, max) {
    this.setPaused(true);
    this.zoomPaused = true;
    for (const c of this.charts.values()) c.u.setScale("x", { min, max });
  }

  resetZoom() {
    const wasZoom = this.zoomPaused;
    this.zoomPaused = false;
    if (wasZoom) this.setPaused(false);
    else this.redraw(true);
  }

  setPaused(p) {
    this.paused = p;
    this.pauseBtn.textContent = p ? "Resume" : "Pause";
    this.pauseBtn.setAttribute("aria-pressed", String(p));
    if (!p) {
      this.zoomPaused = false;
      this.redraw(true);
    }
  }

  /** The rows shown: within the x range of the charts. */
  shownRows() {
    const c = [...this.charts.values()][0];
    let [min, max] = this.windowRange();
    if (c && c.u.scales.x.min != null) [min, max] = [c.u.scales.x.min, c.u.scales.x.max];
    const idx = [];
    for (let i = 0; i < this.t.length; i++) {
      const s = this.t[i] / 1000;
      if (s >= min && s <= max) idx.push(i);
    }
    return idx;
  }

  exportCsv() {
    const cols = [];
    for (const d of this.devices) {
      cols.push([`${d.key}|pos`, `${d.label} position actual (deg)`], [`${d.key}|target`, `${d.label} position target (deg)`], [`${d.key}|speed`, `${d.label} speed (rpm)`]);
      if (d.current) cols.push([`${d.key}|current`, `${d.label} current (mA)`]);
    }
    const q = (s) => (/[",\n]/.test(s) ? `"${s.replaceAll('"', '""')}"` : s);
    const lines = [["unix_ms", ...cols.map(([, h]) => h)].map(q).join(",")];
    const data = new Map(cols.map(([k]) => [k, this.column(k)]));
    for (const i of this.shownRows()) {
      const row = [String(Math.round(this.t[i] * 1000) / 1000)];
      for (const [k] of cols) {
        const v = data.get(k)[i];
        row.push(v == null ? "" : String(v));
      }
      lines.push(row.join(","));
    }
    download(new Blob([lines.join("\n") + "\n"], { type: "text/csv" }), `robobus-plot-${stamp()}.csv`);
    this.studio.toast(`Exported ${lines.length - 1} rows as CSV.`, "ok");
  }

  exportPng() {
    const charts = [...this.charts.values()];
    if (!charts.length) return this.studio.toast(new Error("nothing to export: choose a device"));
    const dpr = devicePixelRatio || 1;
    const pad = 12 * dpr;
    const titleH = 24 * dpr;
    const legendH = 22 * dpr;
    const canvases = charts.map((c) => c.u.ctx.canvas);
    const w = Math.max(...canvases.map((cv) => cv.width)) + 2 * pad;
    const h = canvases.reduce((s, cv) => s + cv.height + titleH + legendH + pad, pad);
    const out = document.createElement("canvas");
    out.width = w;
    out.height = h;
    const ctx = out.getContext("2d");
    ctx.fillStyle = "#fff";
    ctx.fillRect(0, 0, w, h);
    let y = pad;
    charts.forEach((c, n) => {
      ctx.fillStyle = "#111";
      ctx.font = `bold ${14 * dpr}px system-ui, sans-serif`;
      ctx.fillText(`${c.spec.title} (${c.spec.unit})`, pad, y + 16 * dpr);
      y += titleH;
      ctx.drawImage(canvases[n], pad, y);
      y += canvases[n].height;
      let x = pad;
      ctx.font = `${12 * dpr}px system-ui, sans-serif`;
      for (const s of c.defs) {
        ctx.strokeStyle = s.stroke;
        ctx.lineWidth = 2 * dpr;
        ctx.setLineDash(s.dash ? s.dash.map((v) => v * dpr) : []);
        ctx.beginPath();
        ctx.moveTo(x, y + 12 * dpr);
        ctx.lineTo(x + 18 * dpr, y + 12 * dpr);
        ctx.stroke();
        ctx.setLineDash([]);
        ctx.fillStyle = "#111";
        ctx.fillText(s.label, x + 22 * dpr, y + 16 * dpr);
        x += ctx.measureText(s.label).width + 40 * dpr;
      }
      y += legendH + pad;
    });
    out.toBlob((blob) => {
      if (!blob) return this.studio.toast(new Error("the PNG could not be made"));
      download(blob, `robobus-plot-${stamp()}.png`);
      this.studio.toast("Exported the charts as PNG.", "ok");
    }, "image/png");
  }
}

function download(blob, name) {
  const a = el("a", { href: URL.createObjectURL(blob), download: name });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10_000);
}

/** Seconds since the epoch as the local clock time, HH:MM:SS. */
function clock(s) {
  const d = new Date(s * 1000);
  return [d.getHours(), d.getMinutes(), d.getSeconds()].map((n) => String(n).padStart(2, "0")).join(":");
}

function stamp() {
  return new Date().toISOString().replace(/[:.]/g, "-").slice(0, 19);
}

