// A small live chart of one device from the page's history (history.js): its actual
// reading and, for positions, the target the studio commanded (dashed), over the last
// few seconds. The Device and Waveform panels show one beside their controls.

import uPlot from "./vendor/uplot/uPlot.esm.js";
import { el } from "./core.js";

/** The quantities a mini-chart can show: the history's column and its unit. */
const QUANTITIES = {
  position: { col: "pos", unit: "deg", target: true },
  speed: { col: "speed", unit: "rpm", target: false },
  current: { col: "current", unit: "mA", target: false },
};
const DRAW_MS = 100;

/**
 * A mini-chart: `{element, show(key, quantity, label), teardown()}`. `key` is a history
 * device key (`family|bus|id`), `quantity` one of position / speed / current.
 */
export function miniChart(studio, { seconds = 10, height = 150, name = "Live chart" } = {}) {
  const history = studio.history;
  const caption = el("figcaption", {}, name);
  const note = el("p", { className: "hint mini-note", "aria-live": "polite" });
  const fig = el("figure", { className: "chart mini-chart" }, [caption]);
  fig.setAttribute("aria-label", name);
  const box = el("div", { className: "mini-chart-box" }, [fig, note]);
  let key = null;
  let q = QUANTITIES.position;
  let u = null;
  let dirty = true;
  let drawnAt = 0;
  let raf = 0;
  let gone = false;

  const width = () => Math.max(260, (box.clientWidth || 420) - 10);
  function build(label) {
    u?.destroy();
    const series = [
      { label: "time" },
      { label: `${label} actual`, stroke: "#1f5fbf", width: 2 },
      ...(q.target ? [{ label: `${label} target`, stroke: "#c0392b", width: 1.5, dash: [6, 4], spanGaps: true, paths: uPlot.paths.stepped({ align: 1 }) }] : []),
    ];
    u = new uPlot(
      {
        width: width(),
        height,
        series,
        scales: {
          x: { time: true },
          y: { range: (_u, min, max) => (min === max || min == null ? [(min ?? 0) - 1, (max ?? 0) + 1] : uPlot.rangeNum(min, max, 0.1, true)) },
        },
        axes: [
          { stroke: "#333", grid: { stroke: "#e4e7eb" }, space: 60, values: (_u, splits) => splits.map((s) => `${Math.round(s - Date.now() / 1000)} s`) },
          { label: q.unit, stroke: "#333", grid: { stroke: "#e4e7eb" }, size: 50 },
        ],
        cursor: { drag: { x: false, y: false } },
        legend: { live: false },
      },
      [[], [], ...(q.target ? [[]] : [])],
      fig,
    );
    fig.uplot = u; // for the browser tests
  }

  function draw() {
    if (!u || !key) return;
    const tmin = Date.now() - seconds * 1000;
    const r = history.readings(key, tmin);
    let ts = r.t;
    const actual = r[q.col];
    let cols = [actual];
    if (q.target) {
      const extra = history.targetTimes(key, tmin, Date.now());
      if (extra.length) {
        const merged = [...new Set([...ts, ...extra])].sort((a, b) => a - b);
        const at = new Map(ts.map((t, i) => [t, actual[i]]));
        cols = [merged.map((t) => (at.has(t) ? at.get(t) : undefined))];
        ts = merged;
      }
      cols.push(history.targetAt(key, ts));
    }
    u.setData([ts.map((t) => t / 1000), ...cols], false);
    u.setScale("x", { min: tmin / 1000, max: Date.now() / 1000 });
    const h = history.health.get(key);
    note.textContent = h?.silent ? `No reply: ${h.error}. No line is drawn while it is silent.` : "";
    note.className = `hint mini-note ${h?.silent ? "fail" : ""}`;
  }

  const frame = (now) => {
    if (gone) return;
    if (dirty && now - drawnAt >= DRAW_MS && box.isConnected && box.offsetParent !== null) {
      dirty = false;
      drawnAt = now;
      if (u && Math.abs(u.width - width()) > 4) u.setSize({ width: width(), height });
      draw();
    }
    raf = requestAnimationFrame(frame);
  };
  const off = history.onChange(() => {
    dirty = true;
  });
  const tick = setInterval(() => {
    dirty = true; // the window moves on even when no reading comes
  }, 250);
  raf = requestAnimationFrame(frame);

  return {
    element: box,
    show(deviceKey, quantity = "position", label = "") {
      key = deviceKey;
      q = QUANTITIES[quantity] ?? QUANTITIES.position;
      caption.textContent = `${name}: ${label} ${quantity} (${q.unit}), last ${seconds} s`;
      build(label);
      dirty = true;
    },
    teardown() {
      gone = true;
      off();
      clearInterval(tick);
      cancelAnimationFrame(raf);
      u?.destroy();
      u = null;
    },
  };
}
