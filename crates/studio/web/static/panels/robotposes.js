// Robot poses: poses of the robot file's joints by name, wCK servos and WHJ joints alike,
// any set of them. A pose is recorded with `robot.sample` (each joint's angle in the robot
// file's joint frame, what `robobus monitor --robot` shows); "Go to" and "Play" send the
// poses as the trajectory file `robot.play` plays (`time_s`, then a column per joint):
// the joints go from where they are to the first pose no faster than the file allows,
// then from pose to pose in the times given, the whole list as many times as asked.
// "Save trajectory" writes that file (`robobus robot play FILE`, what `robobus robot
// teach` records).

import { field, h } from '../ui.js';

/** The most loops of a scene (a trajectory holds at most 100 000 points and 3600 s). */
const MAX_LOOPS = 1000;
const MAX_S = 600;

/** The trajectory text of `poses` on `joints`, played `loops` times. */
export function trajectoryText(joints, poses, loops = 1) {
  const lines = [`time_s,${joints.join(',')}`];
  let t = 0;
  for (let n = 0; n < loops; n++) {
    for (const [i, p] of poses.entries()) {
      if (n > 0 || i > 0) t += p.s;
      lines.push([round(t, 3), ...joints.map((j) => round(p.deg[j], 3))].join(','));
      if (p.hold > 0) {
        t += p.hold;
        lines.push([round(t, 3), ...joints.map((j) => round(p.deg[j], 3))].join(','));
      }
    }
  }
  return `${lines.join('\n')}\n`;
}

function round(v, digits) {
  const f = 10 ** digits;
  return String(Math.round(v * f) / f);
}

/** The robot poses section: `{element}`; `say(text, kind)` of the panel shows its messages. */
export function robotPoses(studio) {
  const joints = studio.info?.robot ?? null;
  const status = h('p', { class: 'summary', 'aria-live': 'polite', id: 'robot-poses-status' });
  const say = (text, kind = 'info') => {
    status.textContent = text;
    status.className = `summary ${kind === 'error' ? 'fail' : kind === 'ok' ? 'ok' : ''}`;
  };
  if (!joints?.length) {
    return {
      element: h('section', { class: 'card', 'aria-labelledby': 'robot-poses' },
        h('h3', { id: 'robot-poses' }, 'Robot poses'),
        h('p', { class: 'hint' }, 'No robot file: start the studio with ', h('code', {}, '--robot FILE'),
          ' to pose its joints by name (the built-in simulated robot has one).')),
    };
  }

  const boxes = joints.map((j, i) => {
    const box = h('input', { type: 'checkbox', id: `rp-joint-${i}`, value: j.name, checked: true });
    box.addEventListener('change', render);
    return { j, box };
  });
  const pick = h('fieldset', { class: 'devices rp-joints' }, h('legend', {}, 'Joints of the pose'),
    ['wck', 'whj'].map((fam) => {
      const mine = boxes.filter((b) => b.j.family === fam);
      if (!mine.length) return null;
      return h('div', { class: 'rp-family' },
        h('span', { class: 'tag' }, fam === 'wck' ? 'wCK servos' : 'WHJ joints'),
        h('button', { type: 'button', class: 'link', onclick: () => { for (const b of mine) b.box.checked = true; render(); } }, 'all'),
        ' ',
        h('button', { type: 'button', class: 'link', onclick: () => { for (const b of mine) b.box.checked = false; render(); } }, 'none'),
        ' ',
        mine.map(({ j, box }) => h('span', { class: 'check' }, box,
          h('label', { for: box.id, title: `${fam === 'wck' ? 'servo' : 'joint'} ${j.id} on ${j.bus}` }, j.name))));
    }));
  const transition = h('input', { type: 'number', value: 1, min: 0, max: MAX_S, step: 0.1, class: 'num' });
  // robot.play ends in the robot file's safe state where the joints are: a hold gives them
  // the time to arrive.
  const hold = h('input', { type: 'number', value: 0.5, min: 0, max: MAX_S, step: 0.1, class: 'num' });
  const loops = h('input', { type: 'number', value: 1, min: 1, max: MAX_LOOPS, step: 1, class: 'num' });
  const rate = h('input', { type: 'number', value: 50, min: 1, max: 500, step: 1, class: 'num' });
  const prepare = h('input', { type: 'checkbox', id: 'rp-prepare', checked: true });
  const record = h('button', { type: 'button', onclick: recordPose }, 'Record robot pose');
  const play = h('button', { type: 'button', onclick: () => playPoses(null) }, 'Play poses');
  const stop = h('button', { type: 'button', class: 'danger', disabled: true, onclick: () => running?.stop() }, 'Stop poses');
  const dry = h('button', { type: 'button', class: 'preview-btn', 'aria-label': 'Show dry run of the poses',
    onclick: () => { try { studio.preview(playRequest(poses, Number(loops.value))); } catch (e) { say(e.message, 'error'); } } }, 'Preview');
  const save = h('button', { type: 'button', class: 'secondary', onclick: saveFile }, 'Save trajectory');
  const clear = h('button', { type: 'button', class: 'danger', onclick: () => { poses.length = 0; render(); say('Poses cleared.'); } }, 'Clear poses');
  const gate = h('p', { class: 'hint', role: 'note' });
  const head = h('thead');
  const body = h('tbody');
  const table = h('table', { class: 'scene robot-poses', 'aria-labelledby': 'robot-poses-list' }, head, body);

  const element = h('section', { class: 'card', 'aria-labelledby': 'robot-poses' },
    h('h3', { id: 'robot-poses' }, 'Robot poses'),
    h('p', { class: 'hint' }, 'The robot file\'s joints by name, wCK servos and WHJ joints together, any of them. ',
      'Record where they are, then go to a pose or play the list, looped.'),
    pick,
    h('div', { class: 'row' }, field('Transition of new poses (s)', transition), field('Hold of new poses (s)', hold), record),
    h('h4', { id: 'robot-poses-list' }, 'Robot poses'),
    h('div', { class: 'table-wrap' }, table),
    h('div', { class: 'row' }, field('Loops', loops), field('Rate (ticks/s)', rate),
      h('span', { class: 'action' }, play, dry), stop, save, clear),
    h('div', { class: 'row' }, h('span', { class: 'check' }, prepare,
      h('label', { for: 'rp-prepare' }, 'Enable the WHJ joints in position mode first'))),
    gate,
    status);

  /** [{name, s: transition seconds, hold: seconds, deg: {joint: degrees}}] */
  const poses = [];
  let running = null;

  const chosen = () => boxes.filter((b) => b.box.checked).map((b) => b.j.name);
  /** The joints every pose has (a pose records only the joints chosen when it was recorded). */
  const common = (list) => {
    const names = chosen();
    return names.filter((n) => list.every((p) => n in p.deg));
  };
  function playRequest(list, n) {
    if (!list.length) throw new Error('no pose yet: record one first');
    const names = common(list);
    if (!names.length) throw new Error('no joint chosen that every pose has');
    if (!Number.isInteger(n) || n < 1 || n > MAX_LOOPS) throw new Error(`Loops: ${n} is not a whole number 1..${MAX_LOOPS}`);
    return { op: 'robot.play', trajectory: trajectoryText(names, list, n), rate_hz: Number(rate.value) };
  }

  function update() {
    const s = studio.state ?? {};
    const ok = s.controller && s.armed && !s.readOnly;
    play.disabled = !ok || running != null || !poses.length;
    for (const b of body.querySelectorAll('button.go')) b.disabled = !ok || running != null;
    gate.textContent = s.readOnly ? 'Read-only studio: robot poses are recorded, not gone to.'
      : ok ? '' : s.controller ? 'Arm to go to a pose or play them.' : 'Take control and arm to go to a pose or play them.';
  }
  studio.on('control', update);
  studio.on('state', update);

  function render() {
    const names = chosen();
    head.replaceChildren(h('tr', {}, ['#', 'Pose', 'Transition (s)', 'Hold (s)', ...names.map((n) => `${n} (deg)`), 'Actions']
      .map((c) => h('th', { scope: 'col' }, c))));
    body.replaceChildren(...poses.map((p, i) => {
      const n = i + 1;
      const num = (value, label, set, max = MAX_S) => {
        const inp = h('input', { type: 'number', value, min: 0, max, step: 0.1, class: 'num', 'aria-label': label });
        inp.addEventListener('change', () => {
          const v = Number(inp.value);
          if (Number.isFinite(v) && v >= 0 && v <= max) set(v);
          else { say(`${label}: ${inp.value} is not 0..${max}.`, 'error'); render(); }
        });
        return inp;
      };
      const cells = names.map((j) => {
        if (!(j in p.deg)) return h('td', { class: 'hint' }, '—');
        const inp = h('input', { type: 'number', value: round(p.deg[j], 2), step: 0.1, class: 'num deg', 'aria-label': `${j} of ${p.name} (deg)` });
        inp.addEventListener('change', () => {
          const v = Number(inp.value);
          if (Number.isFinite(v) && Math.abs(v) <= 360) p.deg[j] = v;
          else { say(`${j} of ${p.name}: ${inp.value} is not a degree value -360..360.`, 'error'); render(); }
        });
        return h('td', {}, inp);
      });
      const go = h('button', { type: 'button', class: 'small go', 'aria-label': `Go to ${p.name}`, onclick: () => playPoses(i) }, 'Go to');
      return h('tr', {},
        h('td', { class: 'num' }, String(n)),
        h('td', {}, p.name),
        h('td', {}, num(p.s, `Transition of ${p.name} (s)`, (v) => { p.s = v; })),
        h('td', {}, num(p.hold, `Hold of ${p.name} (s)`, (v) => { p.hold = v; })),
        ...cells,
        h('td', {}, h('span', { class: 'row-actions' }, go,
          h('button', { type: 'button', class: 'danger small', 'aria-label': `Delete ${p.name}`, title: 'Delete',
            onclick: () => { poses.splice(i, 1); render(); } }, '✕'))));
    }));
    if (!poses.length) {
      body.append(h('tr', {}, h('td', { colspan: 5 + names.length, class: 'hint' }, 'No robot poses yet: record one.')));
    }
    save.disabled = !poses.length;
    dry.disabled = !poses.length;
    clear.disabled = !poses.length;
    update();
  }
  render();

  let serial = 0;
  async function recordPose() {
    const names = chosen();
    if (!names.length) return say('Choose the joints of the pose first.', 'error');
    try {
      const r = await studio.run({ op: 'robot.sample' });
      const rows = new Map((r.results ?? []).map((x) => [x.id, x]));
      const silent = names.filter((n) => !rows.get(n) || rows.get(n).kind);
      if (silent.length) {
        const why = rows.get(silent[0])?.error ?? 'no row';
        return say(`Not recorded: ${silent.join(', ')} did not answer (${why}).`, 'error');
      }
      serial += 1;
      const deg = {};
      for (const n of names) deg[n] = rows.get(n).position_deg;
      poses.push({ name: `pose ${serial}`, s: Number(transition.value) || 0, hold: Number(hold.value) || 0, deg });
      render();
      say(`Recorded pose ${serial}: ${names.length} joints.`, 'ok');
    } catch (e) {
      say(`Record failed${e?.kind ? ` (${e.kind})` : ''}: ${e?.message ?? e}`, 'error');
    }
  }

  /** The WHJ joints of the trajectory enabled in position mode (robot.play refuses others). */
  async function prepareWhj(names) {
    const byBus = new Map();
    for (const j of joints) {
      if (j.family !== 'whj' || !names.includes(j.name)) continue;
      if (!byBus.has(j.bus)) byBus.set(j.bus, []);
      byBus.get(j.bus).push(j.id);
    }
    for (const [bus, ids] of byBus) {
      const sel = { bus, joints: ids.join(',') };
      const st = await studio.run({ op: 'whj.status', ...sel });
      const bad = (st.results ?? []).find((x) => x.kind);
      if (bad) throw Object.assign(new Error(`joint ${bad.id}: ${bad.error}`), { kind: bad.kind });
      const notPos = st.results.filter((x) => x.mode !== 'position').map((x) => x.id);
      if (notPos.length) await studio.run({ op: 'whj.mode', bus, joints: notPos.join(','), mode: 'position' });
      const off = st.results.filter((x) => !x.enabled).map((x) => x.id);
      if (off.length) await studio.run({ op: 'whj.enable', bus, joints: off.join(',') });
    }
  }

  /** Go to pose `index` (null: play every pose, looped). */
  async function playPoses(index) {
    let req;
    const list = index == null ? poses : [poses[index]];
    try {
      req = playRequest(list, index == null ? Number(loops.value) : 1);
    } catch (e) {
      return say(e.message, 'error');
    }
    const what = index == null ? `${poses.length} poses × ${loops.value}` : poses[index].name;
    stop.disabled = false;
    running = { stop() {} };
    update();
    try {
      if (prepare.checked) await prepareWhj(common(list));
      say(`Going: ${what}…`);
      running = studio.runLong(req);
      const r = await running.promise;
      const failed = (r.results ?? []).filter((x) => x.kind);
      if (r.failed || failed.length) {
        say(`${what}: failed (${r.failed ?? failed[0].kind}): ${r.error ?? failed[0].error}`, 'error');
      } else {
        const s = r.summary ?? {};
        const worst = Math.max(0, ...(r.results ?? []).map((x) => x.tracking_max_deg ?? 0));
        say(`Done: ${what} in ${round((s.lead_in_s ?? 0) + (s.duration_s ?? 0), 2)} s (lead-in ${round(s.lead_in_s ?? 0, 2)} s); largest tracking error ${round(worst, 2)} deg.`, 'ok');
      }
    } catch (e) {
      say(e?.kind === 'interrupted' ? 'Stopped: the joints were left in the robot file\'s safe state.'
        : `${what}: ${e?.kind ? `(${e.kind}) ` : ''}${e?.message ?? e}`, 'error');
    } finally {
      running = null;
      stop.disabled = true;
      update();
    }
  }

  function saveFile() {
    let text;
    try {
      text = playRequest(poses, Number(loops.value)).trajectory;
    } catch (e) {
      return say(e.message, 'error');
    }
    const a = h('a', { href: URL.createObjectURL(new Blob([text], { type: 'text/csv' })), download: 'poses.csv' });
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 10000);
    say('Saved poses.csv: play it with `robobus robot play poses.csv`.', 'ok');
  }

  return { element };
}
