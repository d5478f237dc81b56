// Waveform: a sine or square test signal on one WHJ joint (`whj.wave`), with its progress,
// a Stop button, a live chart of the joint against the signal asked, and the tracking
// statistics of the report's summary (the figures `robobus whj wave` prints below its
// table). Before a position wave starts, its plan from where the joint is now says how
// many set-points the step limiter would change (clamp): a wave with any does not start
// until "Run anyway" is pressed.

import { field, devicePicker, h } from '../ui.js';
import { miniChart } from '../minichart.js';
import { deviceKey } from '../history.js';

/** A small element builder: h('button', {onclick}, 'Text'); attributes as attributes. */

const UNITS = { position: 'deg', speed: 'RPM', current: 'mA' };

// The summary's fields in the CLI's order, what they mean, and their unit (`unit`: the
// loop's unit, which the report names).
const STATS = [
  ['cycles', 'Frames sent', ''],
  ['complete', 'Frames answered', ''],
  ['missing_replies', 'Missing replies', ''],
  ['missing_at_end', 'Missing in a row at the end', ''],
  ['deadline_misses', 'Deadline misses (> 1 period late)', ''],
  ['overruns', 'Overruns (exchange > 1 period)', ''],
  ['clamped', 'Set-points the step limiter changed', ''],
  ['tracking_rms', 'Tracking error, RMS', 'unit'],
  ['tracking_max', 'Tracking error, max', 'unit'],
  ['round_trip_p50_us', 'Round trip, median', 'µs'],
  ['round_trip_p99_us', 'Round trip, 99th percentile', 'µs'],
  ['round_trip_max_us', 'Round trip, max', 'µs'],
  ['stale', 'Last frame unanswered', ''],
];

/** The value a wave asks for `t` seconds after its first frame (the signal `robobus whj wave` sends before its step limiter). */
function waveAt(r, t) {
  const s = Math.sin(2 * Math.PI * r.frequency * t);
  if (r.shape === 'square') return r.offset + (s >= 0 ? r.amplitude : -r.amplitude);
  return r.offset + r.amplitude * s;
}

function show(v) {
  if (v == null) return '–';
  if (typeof v === 'boolean') return v ? 'yes' : 'no';
  if (typeof v === 'number' && !Number.isInteger(v)) return v.toPrecision(4);
  return String(v);
}

export default {
  id: 'waveform',
  title: 'Waveform',
  mount(element, studio) {
    const picker = devicePicker(studio, { families: ['whj'], label: 'Joint' });
    const num = (value, attrs = {}) =>
      h('input', { type: 'number', value, step: 'any', required: true, class: 'num', ...attrs });
    const shape = h('select', {}, h('option', { value: 'sine' }, 'sine'), h('option', { value: 'square' }, 'square'));
    const mode = h('select', {}, Object.keys(UNITS).map((m) => h('option', { value: m }, m)));
    const amplitude = num(10, { min: 0 });
    const offset = num(0);
    const frequency = num(0.5, { min: 0.01, max: 20 });
    const duration = num(4, { min: 0.01, max: 600 });
    const rate = num(200, { min: 1, max: 1000, step: 1 });
    const onStop = h('select', {}, h('option', { value: 'hold' }, 'hold'), h('option', { value: 'disable' }, 'disable'));
    const prepare = h('input', { type: 'checkbox', id: 'wave-prepare', checked: true });

    const start = h('button', { type: 'submit' }, 'Start wave');
    const stop = h('button', { type: 'button', class: 'danger', disabled: true, onclick: () => running?.stop() }, 'Stop wave');
    const dry = h('button', { type: 'button', class: 'secondary', 'aria-label': 'Show dry run of the wave', onclick: () => form.reportValidity() && studio.preview(request()) }, 'Show dry run');
    const gate = h('p', { class: 'hint', role: 'note' });
    const progress = h('progress', { 'aria-label': 'Wave progress', max: 1, value: 0 });
    const progressText = h('span', { class: 'progress-text' });
    const status = h('p', { role: 'status', 'aria-live': 'polite', class: 'summary' });
    const results = h('div', { class: 'wave-results' });
    const chart = miniChart(studio, { name: 'Wave chart', seconds: 10 });
    const warnText = h('div', {});
    const anyway = h('button', { type: 'button', class: 'danger', onclick: runAnyway }, 'Run anyway');
    const cancelWarn = h('button', { type: 'button', class: 'secondary', onclick: () => { confirmed = null; warn.hidden = true; say('Not started: nothing was sent.'); } }, 'Cancel');
    const warn = h('div', { class: 'clamp-warning', role: 'alert', hidden: true },
      warnText, h('div', { class: 'row' }, anyway, cancelWarn));

    const unitField = (label, input, unit) => {
      const f = field(`${label} (${unit})`, input);
      f.dataset.label = label;
      return f;
    };
    const amplitudeField = unitField('Amplitude', amplitude, 'deg');
    const offsetField = unitField('Offset', offset, 'deg');

    const form = h('form', { 'aria-label': 'Wave signal', novalidate: false },
      h('div', { class: 'row' }, picker.element, field('Shape', shape), field('Mode', mode)),
      h('div', { class: 'row' }, amplitudeField, offsetField,
        unitField('Frequency', frequency, 'Hz'), unitField('Duration', duration, 's'),
        unitField('Rate', rate, 'frames/s'), field('On stop', onStop)),
      h('div', { class: 'row' }, h('span', { class: 'check' }, prepare,
        h('label', { for: 'wave-prepare' }, 'Enable the joint and set its mode first'))),
      h('div', { class: 'row' }, start, stop, dry),
      warn,
      gate);

    element.append(
      h('h2', {}, 'Waveform'),
      h('p', { class: 'lead' }, 'A sine or square test signal on one WHJ joint, sent as servo frames at a fixed rate ',
        '(', h('code', {}, 'robobus whj wave'), '). The offset is the bias the signal swings around; ',
        'the tracking error compares each reply with the value requested one frame before.'),
      h('div', { class: 'columns' },
        h('section', { class: 'card', 'aria-labelledby': 'wave-signal' }, h('h3', { id: 'wave-signal' }, 'Signal'), form),
        h('section', { class: 'card', 'aria-labelledby': 'wave-result' }, h('h3', { id: 'wave-result' }, 'Run'),
          h('div', { class: 'progress' }, progress, progressText), status, chart.element, results)));

    let running = null;
    /** The request the user chose to run anyway though its set-points would be clamped (JSON). */
    let confirmed = null;

    const QUANTITY = { position: 'position', speed: 'speed', current: 'current' };
    function follow() {
      const d = picker.get();
      if (d) chart.show(deviceKey('whj', d.bus, d.id), QUANTITY[mode.value], `joint ${d.id}`);
    }
    picker.onChange(follow);
    mode.addEventListener('change', follow);
    element.addEventListener('studio:show', follow);
    follow();

    mode.addEventListener('change', () => {
      for (const f of [amplitudeField, offsetField]) {
        f.querySelector('label').textContent = `${f.dataset.label} (${UNITS[mode.value]})`;
      }
    });

    function request() {
      const d = picker.get();
      const r = {
        op: 'whj.wave',
        joint: d?.id ?? 1,
        shape: shape.value,
        mode: mode.value,
        amplitude: Number(amplitude.value),
        frequency: Number(frequency.value),
        offset: Number(offset.value),
        duration: Number(duration.value),
        rate_hz: Number(rate.value),
        on_stop: onStop.value,
      };
      if (d?.bus && studio.buses('whj').length > 1) r.bus = d.bus;
      return r;
    }

    function update() {
      const s = studio.state ?? {};
      const ok = s.armed && s.controller && !s.readOnly;
      start.disabled = !ok || running != null;
      gate.textContent = s.readOnly ? 'Read-only studio: waves are not served.'
        : ok ? '' : 'Take control and arm to run a wave.';
    }
    studio.on('control', update);
    studio.on('state', update);
    update();

    // The joint must be enabled and in the wave's loop: the CLI asks for `robobus whj mode`
    // and `whj enable` first; here the checkbox does both when needed.
    async function prepareJoint(r) {
      const sel = { joints: String(r.joint), ...(r.bus ? { bus: r.bus } : {}) };
      const st = await studio.run({ op: 'whj.status', ...sel });
      const row = st.results?.[0] ?? {};
      if (row.kind) throw Object.assign(new Error(row.error), { kind: row.kind });
      if (row.mode !== r.mode) await studio.run({ op: 'whj.mode', ...sel, mode: r.mode });
      if (!row.enabled) await studio.run({ op: 'whj.enable', ...sel });
    }

    /**
     * A clamp the warning stops for: a set-point changed by at least this much (deg), the
     * position tolerance whj.move settles to. A sine started from rest is clamped by
     * hundredths of a degree while its speed builds up (the acceleration limit): counted in
     * the run's statistics, but not worth a question before every wave.
     */
    const NOTICEABLE_DEG = 0.1;

    /**
     * How many of a position wave's set-points its step limiter would change, planned from
     * where the joint is now (`whj.status`, then the wave's plan with `from` that position):
     * the plan's note `N of M set-point(s) clamped`, and its note on a lead-in when it has
     * one. Null for speed and current waves.
     */
    async function clampCheck(r) {
      if (r.mode !== 'position') return null;
      const sel = { joints: String(r.joint), ...(r.bus ? { bus: r.bus } : {}) };
      const st = await studio.run({ op: 'whj.status', ...sel });
      const row = st.results?.[0] ?? {};
      if (row.kind) throw Object.assign(new Error(row.error), { kind: row.kind });
      const from = row.position_deg;
      const plan = await studio.plan({ ...r, from });
      const notes = plan.notes ?? [];
      const m = notes.map((n) => /^(\d+) of (\d+) set-point\(s\) clamped, by up to ([\d.]+) deg/.exec(n)).find(Boolean);
      // Why, when the plan says more than the count (a lead-in).
      const why = notes.filter((n) => /counted as clamped/.test(n));
      return { count: m ? Number(m[1]) : 0, frames: m ? Number(m[2]) : 0, by: m ? Number(m[3]) : 0, from, notes: why };
    }

    function runAnyway() {
      confirmed = JSON.stringify(request());
      warn.hidden = true;
      form.requestSubmit();
    }

    function showStats(report) {
      const s = report.summary ?? {};
      const unit = s.unit ?? UNITS[mode.value];
      const last = report.results?.[0];
      const table = h('table', { class: 'stats' },
        h('caption', {}, `Tracking statistics, joint ${last?.id ?? ''}`),
        h('thead', {}, h('tr', {}, h('th', { scope: 'col' }, 'Statistic'), h('th', { scope: 'col' }, 'Value'),
          h('th', { scope: 'col' }, 'Unit'), h('th', { scope: 'col' }, 'Field'))),
        h('tbody', {}, STATS.filter(([k]) => k in s).map(([k, label, u]) =>
          h('tr', { 'data-field': k },
            h('th', { scope: 'row' }, label),
            h('td', { class: 'num' }, show(s[k])),
            h('td', {}, u === 'unit' ? unit : u),
            h('td', { class: 'hint' }, h('code', {}, k))))));
      const fb = last && !last.kind
        ? h('p', { class: 'hint' }, `Last feedback: ${show(last.position_deg)} deg, ${show(last.speed_rpm)} RPM, `,
          `${show(last.current_ma)} mA, ${last.enabled ? 'enabled' : 'disabled'}, error: ${last.error}.`)
        : null;
      results.replaceChildren(table, fb);
    }

    function say(text, kind = '') {
      status.textContent = text;
      status.className = `summary ${kind}`;
    }

    form.addEventListener('submit', async (ev) => {
      ev.preventDefault();
      if (!form.reportValidity()) return;
      const r = request();
      const asked = JSON.stringify(r);
      if (confirmed !== asked) confirmed = null;
      warn.hidden = true;
      if (running) return;
      if (!confirmed) {
        try {
          say('Checking the wave against where the joint is…');
          const c = await clampCheck(r);
          if (c && c.count > 0 && c.by >= NOTICEABLE_DEG) {
            warnText.replaceChildren(
              h('strong', {}, `${c.count} of ${c.frames} set-points would be clamped, by up to ${c.by} deg`),
              ` (the joint is at ${c.from.toFixed(2)} deg): there the joint is sent the step limiter's set-points, not the wave asked`,
              c.notes.length ? h('ul', {}, c.notes.map((n) => h('li', {}, n))) : ' (its speed and acceleration limits).');
            warn.hidden = false;
            say('Not started: its set-points would be clamped. Run anyway, or move the joint nearer the offset first.', 'fail');
            anyway.focus();
            return;
          }
        } catch (e) {
          say(`Wave not started${e?.kind ? ` (${e.kind})` : ''}: ${e?.message ?? e}`, 'fail');
          return;
        }
      }
      confirmed = null;
      results.replaceChildren();
      progress.max = 1;
      progress.value = 0;
      progressText.textContent = '';
      say('Starting…');
      stop.disabled = false;
      running = { stop() {} };
      update();
      let seg = null;
      try {
        if (prepare.checked) await prepareJoint(r);
        running = studio.runLong(r, (p) => {
          if (r.mode === 'position' && p.done != null) {
            // The signal asked, drawn as the target from the first frame on. The first
            // frame went `done` periods before this progress arrived (it cannot have gone
            // later): the earliest such estimate is the closest.
            const t0 = Date.now() - (p.done / r.rate_hz) * 1000;
            if (!seg) {
              const ask = { ...r };
              const s0 = studio.history.addWave('whj', r.bus ?? null, r.joint, t0, t0 + r.duration * 1000,
                (t) => waveAt(ask, (t - s0.t0) / 1000));
              seg = s0;
            } else if (t0 < seg.t0) {
              seg.t1 -= seg.t0 - t0;
              seg.t0 = t0;
            }
          }
          if (p.total) progress.max = p.total;
          progress.value = p.done ?? 0;
          progressText.textContent = `${p.stage ?? ''} ${p.done ?? 0}${p.total ? ` / ${p.total}` : ''}${p.note ? ` · ${p.note}` : ''}`;
        });
        say(`Wave running on joint ${r.joint}…`);
        const report = await running.promise;
        progress.value = progress.max;
        if (report.failed) say(`Wave ended with a failure (${report.failed}): ${report.error ?? ''}`, 'fail');
        else say(`Wave done: ${report.summary?.cycles ?? 0} frames.`, 'ok');
        showStats(report);
      } catch (e) {
        if (e?.kind === 'interrupted') say(`Stopped: the joint was brought to its safe state (${r.on_stop}).`, 'fail');
        else say(`Wave failed${e?.kind ? ` (${e.kind})` : ''}: ${e?.message ?? e}`, 'fail');
      } finally {
        studio.history.endWave(seg, Date.now());
        running = null;
        stop.disabled = true;
        update();
      }
    });
  },
};
