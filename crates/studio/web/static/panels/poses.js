// Poses (Motion Builder). First the robot file's poses (robotposes.js): its joints by name,
// wCK and WHJ together, recorded with `robot.sample`, gone to and played (looped) with
// `robot.play`. Below, the wCK keyframe scene: record wCK poses by hand, edit them into a
// scene and play it. The scene is the CLI's keyframe motion file (`robobus wck play --help`):
//
//   # robobus keyframe motion
//   # servos 0 1 2
//   torque 0
//   pose 1000 127 127 127     positions of servos 0, 1, 2, … ; ms = transition time
//   hold 200
//
// so "Save file" writes what `robobus wck teach` writes and `robobus wck play` plays,
// and "Load file" reads such a file (validated by the library's parser on the server).

import { field, h, panelStyles, errorPosition } from '../ui.js';
import { robotPoses } from './robotposes.js';

const MAX_MS = 600000;

/** `"0-3,5"` → [0, 1, 2, 3, 5] (throws on bad text). */
export function parseIds(text) {
  const ids = [];
  for (const part of String(text).split(',').map((s) => s.trim()).filter(Boolean)) {
    const m = /^(\d+)(?:\s*-\s*(\d+))?$/.exec(part);
    if (!m) throw new Error(`"${part}" is not an ID or a range (like 0-15)`);
    const a = Number(m[1]);
    const b = m[2] == null ? a : Number(m[2]);
    if (b < a) throw new Error(`range ${part} runs backwards`);
    for (let i = a; i <= b; i++) ids.push(i);
  }
  if (!ids.length) throw new Error('no servo given');
  return ids;
}

/** The lines before the first step in the text of a scene. */
const HEADER_LINES = 3;

/** The keyframe text of a scene (the format `Motion::to_text` writes). */
export function sceneText(servos, torque, rows) {
  const lines = ['# robobus keyframe motion', `# servos ${servos.join(' ')}`, `torque ${torque}`];
  for (const r of rows) {
    lines.push(r.kind === 'hold' ? `hold ${r.ms}` : `pose ${r.ms} ${r.positions.join(' ')}`);
  }
  return `${lines.join('\n')}\n`;
}

/** Reads keyframe text the server's parser accepted: {torque, rows}. */
export function parseScene(text) {
  let torque = 0;
  const rows = [];
  for (const line of text.split(/\r?\n/)) {
    const t = line.split('#')[0].trim().split(/\s+/).filter(Boolean);
    if (!t.length) continue;
    if (t[0] === 'torque') torque = Number(t[1]);
    else if (t[0] === 'hold') rows.push({ kind: 'hold', ms: Number(t[1]) });
    else if (t[0] === 'pose') rows.push({ kind: 'pose', ms: Number(t[1]), positions: t.slice(2).map(Number) });
  }
  return { torque, rows };
}

export default {
  id: 'poses',
  title: 'Poses',
  mount(element, studio) {
    panelStyles('poses');
    const wckBuses = studio.buses?.('wck') ?? [];
    const known = (studio.ids?.('wck') ?? []).filter((d) => d.bus === wckBuses[0]).map((d) => d.id);
    const defaultIds = known.length && known.every((v, i) => v === i) ? `0-${known.length - 1}` : '0-15';

    const bus = wckBuses.length > 1
      ? h('select', {}, wckBuses.map((b) => h('option', { value: b }, b)))
      : null;
    const servos = h('input', { type: 'text', value: defaultIds, size: 8, 'aria-describedby': 'poses-servos-hint' });
    const transition = h('input', { type: 'number', value: 1000, min: 0, max: MAX_MS, step: 1, class: 'num' });
    const torque = h('select', {},
      [0, 1, 2, 3, 4].map((t) => h('option', { value: t }, t === 0 ? '0 (max)' : t === 4 ? '4 (min)' : String(t))));
    const rate = h('input', { type: 'number', value: 50, min: 1, max: 200, step: 1, class: 'num' });

    const passive = h('button', { type: 'button', class: 'secondary', onclick: makePassive }, 'Make passive');
    const record = h('button', { type: 'button', onclick: recordPose }, 'Record pose');
    const addHold = h('button', { type: 'button', class: 'secondary', onclick: () => { rows.push({ kind: 'hold', ms: 500 }); render(); } }, 'Add hold');
    const play = h('button', { type: 'button', onclick: playScene }, 'Play scene');
    const stop = h('button', { type: 'button', class: 'danger', disabled: true, onclick: () => playing?.stop() }, 'Stop scene');
    const dry = h('button', { type: 'button', class: 'preview-btn', 'aria-label': 'Show dry run of the scene',
      onclick: () => { try { studio.preview(playRequest()); } catch (e) { say(`Servos: ${e.message}`, 'error'); } } }, 'Preview');
    const save = h('button', { type: 'button', class: 'secondary', onclick: saveFile }, 'Save file');
    const clear = h('button', { type: 'button', class: 'danger', onclick: () => { rows.length = 0; render(); say('Scene cleared.'); } }, 'Clear scene');
    const load = h('input', { type: 'file', id: 'poses-load', accept: '.txt,.motion,.keyframes,text/plain', onchange: loadFile });
    const gate = h('p', { class: 'hint', role: 'note' });
    const progress = h('progress', { 'aria-label': 'Scene progress', max: 1, value: 0 });
    const progressText = h('span', { class: 'progress-text' });
    const status = h('p', { role: 'status', 'aria-live': 'polite', class: 'summary' });
    const body = h('tbody');
    const table = h('table', { class: 'scene', 'aria-labelledby': 'poses-scene' },
      h('thead', {}, h('tr', {}, ['#', 'Step', 'Transition (ms)', 'Positions (servo 0, 1, …)', 'Actions']
        .map((c) => h('th', { scope: 'col' }, c)))),
      body);

    element.append(
      h('h2', {}, 'Poses'),
      h('p', { class: 'lead' }, 'Motion builder. Robot poses: the robot file\'s joints by name, both families, ',
        'recorded where they are, gone to, and played in a loop (', h('code', {}, 'robot.play'), '). ',
        'The wCK keyframe scene below: make the servos passive, pose them by hand, record each pose, ',
        'then edit the scene and play it; it is the keyframe file of ', h('code', {}, 'robobus wck teach'),
        ' and ', h('code', {}, 'robobus wck play'), ': save it, or load one.'),
      robotPoses(studio).element,
      h('h3', { class: 'section-title' }, 'wCK keyframe scene'),
      h('section', { class: 'card', 'aria-labelledby': 'poses-record' },
        h('h3', { id: 'poses-record' }, 'Record'),
        h('div', { class: 'row' },
          bus ? field('Bus', bus) : null,
          field('Servos', servos),
          field('Transition of new poses (ms)', transition),
          passive, record, addHold),
        h('p', { id: 'poses-servos-hint', class: 'hint' },
          'Servos 0 to N−1 (like 0-15): a keyframe pose lists the positions of servos 0, 1, 2, … in order.')),
      h('section', { class: 'card', 'aria-labelledby': 'poses-scene' },
        h('h3', { id: 'poses-scene' }, 'Scene'),
        h('div', { class: 'row' }, field('Torque', torque), field('Rate (moves/s)', rate),
          h('span', { class: 'action' }, play, dry), stop,
          h('span', { class: 'progress' }, progress, progressText)),
        gate,
        table,
        h('p', { class: 'hint' }, 'Each time is the transition from the step before; the first pose is sent at once ',
          'and its time is the time allowed to reach it. A hold keeps the pose for its time.'),
        h('div', { class: 'row' }, save,
          h('span', { class: 'file-load' }, h('label', { for: 'poses-load' }, 'Load keyframe file'), load),
          clear),
        status));

    /** The scene: {kind: 'pose', ms, positions} or {kind: 'hold', ms}. */
    const rows = [];
    let playing = null;

    function say(text, kind = 'info') {
      status.textContent = text;
      status.className = `summary ${kind === 'error' ? 'fail' : kind === 'ok' ? 'ok' : ''}`;
    }
    function ids() {
      const list = parseIds(servos.value);
      if (!list.every((v, i) => v === i)) {
        throw new Error('the servos must be 0 to N−1 (a pose lists servos 0, 1, 2, … in order)');
      }
      if (list.length > 31) throw new Error('a pose drives at most 31 servos (0..30)');
      return list;
    }
    const sel = () => (bus ? { bus: bus.value } : {});
    const motion = () => sceneText(ids(), Number(torque.value), rows);
    function playRequest() {
      return { op: 'wck.play', ...sel(), motion: motion(), rate_hz: Number(rate.value) };
    }

    function update() {
      const s = studio.state ?? {};
      const { controller, armed } = s;
      passive.disabled = !controller || s.readOnly;
      play.disabled = !(controller && armed) || s.readOnly || playing != null;
      gate.textContent = s.readOnly ? 'Read-only studio: recording only.'
        : controller && armed ? '' : controller ? 'Arm to play the scene.' : 'Take control and arm to play the scene.';
    }
    studio.on('control', update);
    studio.on('state', update);
    update();

    function move(i, by) {
      const j = i + by;
      if (j < 0 || j >= rows.length) return;
      [rows[i], rows[j]] = [rows[j], rows[i]];
      render();
      body.rows[j]?.querySelector(`button[data-move="${by}"]`)?.focus();
    }

    function render() {
      body.replaceChildren(...rows.map((r, i) => {
        const n = i + 1;
        const ms = h('input', { type: 'number', value: r.ms, min: 0, max: MAX_MS, step: 1,
          'aria-label': `Transition time of step ${n} (ms)`, class: 'num' });
        ms.addEventListener('change', () => {
          const v = Number(ms.value);
          if (Number.isInteger(v) && v >= 0 && v <= MAX_MS) r.ms = v;
          else { ms.value = r.ms; say(`Step ${n}: a time is 0..${MAX_MS} ms.`, 'error'); }
        });
        let positions = h('span', { class: 'hint' }, 'keep the pose');
        if (r.kind === 'pose') {
          positions = h('input', { type: 'text', value: r.positions.join(' '), class: 'positions',
            'aria-label': `Positions of step ${n}`, spellcheck: 'false' });
          positions.addEventListener('change', (ev) => {
            const vals = ev.target.value.trim().split(/[\s,]+/).map(Number);
            if (vals.length === r.positions.length && vals.every((v) => Number.isInteger(v) && v >= 0 && v <= 254)) {
              r.positions = vals;
            } else {
              ev.target.value = r.positions.join(' ');
              say(`Step ${n}: ${r.positions.length} positions, each 0..254.`, 'error');
            }
          });
        }
        return h('tr', {},
          h('td', { class: 'num' }, String(n)),
          h('td', {}, r.kind),
          h('td', {}, ms),
          h('td', {}, positions),
          h('td', {}, h('span', { class: 'row-actions' },
            h('button', { type: 'button', class: 'secondary small', 'data-move': -1, disabled: i === 0, 'aria-label': `Move step ${n} up`, title: 'Move up', onclick: () => move(i, -1) }, '↑'),
            h('button', { type: 'button', class: 'secondary small', 'data-move': 1, disabled: i === rows.length - 1, 'aria-label': `Move step ${n} down`, title: 'Move down', onclick: () => move(i, 1) }, '↓'),
            h('button', { type: 'button', class: 'danger small', 'aria-label': `Delete step ${n}`, title: 'Delete', onclick: () => { rows.splice(i, 1); render(); } }, '✕'))));
      }));
      if (!rows.length) {
        body.append(h('tr', {}, h('td', { colspan: 5, class: 'hint' }, 'No poses yet: record one, or load a keyframe file.')));
      }
      save.disabled = !rows.length;
      dry.disabled = !rows.length;
      clear.disabled = !rows.length;
    }
    render();

    async function makePassive() {
      try {
        const r = await studio.run({ op: 'wck.passive', ...sel(), ids: servos.value });
        const bad = (r.results ?? []).filter((x) => x.kind);
        say(bad.length
          ? `Passive, except servo ${bad.map((x) => x.id).join(', ')} (${bad[0].kind}): ${bad[0].error}`
          : `Servos ${servos.value} are passive: move them by hand, then record.`, bad.length ? 'error' : 'ok');
      } catch (e) {
        say(`Make passive failed${e?.kind ? ` (${e.kind})` : ''}: ${e?.message ?? e}`, 'error');
      }
    }

    async function recordPose() {
      let list;
      try {
        list = ids();
      } catch (e) {
        return say(`Servos: ${e.message}`, 'error');
      }
      const first = rows.find((r) => r.kind === 'pose');
      if (first && first.positions.length !== list.length) {
        return say(`The scene's poses list ${first.positions.length} servos, not ${list.length}: clear the scene or change Servos.`, 'error');
      }
      try {
        const r = await studio.run({ op: 'wck.status', ...sel(), ids: list });
        const bad = (r.results ?? []).filter((x) => x.kind);
        if (bad.length) {
          return say(`Not recorded: servo ${bad.map((x) => x.id).join(', ')} did not answer (${bad[0].kind}).`, 'error');
        }
        const byId = new Map(r.results.map((x) => [x.id, x.position]));
        rows.push({ kind: 'pose', ms: Number(transition.value) || 0, positions: list.map((i) => byId.get(i)) });
        render();
        say(`Recorded step ${rows.length}.`, 'ok');
      } catch (e) {
        say(`Record failed${e?.kind ? ` (${e.kind})` : ''}: ${e?.message ?? e}`, 'error');
      }
    }

    async function playScene() {
      let req;
      try {
        req = playRequest();
      } catch (e) {
        return say(`Servos: ${e.message}`, 'error');
      }
      say('Playing…');
      progress.value = 0;
      stop.disabled = false;
      playing = studio.runLong(req, (p) => {
        if (p.total) progress.max = p.total;
        progress.value = p.done ?? 0;
        progressText.textContent = `${p.stage ?? ''} ${p.done ?? 0}${p.total ? ` / ${p.total}` : ''}${p.note ? ` · ${p.note}` : ''}`;
      });
      update();
      try {
        const r = await playing.promise;
        progress.value = progress.max;
        const s = r.summary ?? {};
        say(`Played: ${s.moves ?? '?'} moves in ${s.duration_ms ?? '?'} ms; last pose ${(s.last_positions ?? []).join(' ')}.`, 'ok');
      } catch (e) {
        const pos = errorPosition(e?.message);
        say(e?.kind === 'interrupted' ? 'Stopped: the servos hold where they are.'
          : pos ? `Step ${pos.line - HEADER_LINES}: ${pos.message}`
            : `Play failed${e?.kind ? ` (${e.kind})` : ''}: ${e?.message ?? e}`, 'error');
      } finally {
        playing = null;
        stop.disabled = true;
        update();
      }
    }

    function saveFile() {
      let text;
      try {
        text = motion();
      } catch (e) {
        return say(`Servos: ${e.message}`, 'error');
      }
      const a = h('a', { href: URL.createObjectURL(new Blob([text], { type: 'text/plain' })), download: 'motion.txt' });
      document.body.append(a);
      a.click();
      a.remove();
      setTimeout(() => URL.revokeObjectURL(a.href), 10000);
      say('Saved motion.txt: play it with `robobus wck play motion.txt`.', 'ok');
    }

    async function loadFile() {
      const file = load.files?.[0];
      if (!file) return;
      const text = await file.text();
      load.value = '';
      try {
        await studio.plan({ op: 'wck.play', ...sel(), motion: text });
      } catch (e) {
        const pos = errorPosition(e?.message);
        return say(pos ? `${file.name}: line ${pos.line}, column ${pos.column}: ${pos.message}`
          : `${file.name}: ${e?.message ?? e}`, 'error');
      }
      const scene = parseScene(text);
      const n = scene.rows.find((r) => r.kind === 'pose')?.positions.length ?? 0;
      rows.splice(0, rows.length, ...scene.rows);
      torque.value = String(scene.torque);
      if (n) servos.value = n === 1 ? '0' : `0-${n - 1}`;
      render();
      say(`Loaded ${file.name}: ${rows.length} steps, servos 0 to ${n - 1}.`, 'ok');
    }
  },
};
