// Preview: any request as JSON, its dry run (the exact bytes / frames `--dry-run` prints,
// what it needs confirmed, its effect) and, on demand, the run itself. Other panels open
// it with a request filled in (`studio.preview(request)`).

import { h, panelStyles } from '../ui.js';

// Requests that report progress while they run (their report comes at the end).
const LONG = new Set(['whj.wave', 'whj.move', 'whj.speed', 'whj.current', 'wck.play', 'wck.teach',
  'wck.wheel', 'wck.scan', 'whj.scan']);

const EFFECTS = {
  read: 'read: changes nothing on a device',
  configure: 'configure: changes a setting, moves nothing',
  motion: 'motion: moves or energises a device (needs arming)',
};

/** Where `JSON.parse` failed: {line, column} (1-based), from its message when it says, else
 * the end of the longest prefix of `text` that can still begin a JSON document. */
function jsonErrorAt(text, message) {
  const m = /line (\d+) column (\d+)/.exec(message);
  if (m) return { line: Number(m[1]), column: Number(m[2]) };
  const p = /position (\d+)/.exec(message);
  const at = p ? Number(p[1]) : viablePrefix(text);
  const before = text.slice(0, at).split('\n');
  return { line: before.length, column: before.at(-1).length + 1 };
}

/** Whether `prefix` can begin a JSON document (it fails only for want of more text). */
function viable(prefix) {
  try {
    JSON.parse(prefix);
    return true;
  } catch (e) {
    if (/end of JSON input/.test(e.message)) return true;
    const p = /position (\d+)/.exec(e.message);
    return p ? Number(p[1]) >= prefix.length : false;
  }
}

/** The length of the longest viable prefix (binary search: a prefix of a viable one is viable). */
function viablePrefix(text) {
  let lo = 0;
  let hi = text.length;
  while (lo < hi) {
    const mid = Math.ceil((lo + hi) / 2);
    if (viable(text.slice(0, mid))) lo = mid;
    else hi = mid - 1;
  }
  return lo;
}

export default {
  id: 'preview',
  title: 'Preview',
  mount(element, studio) {
    panelStyles('preview');
    const editor = h('textarea', { id: 'preview-request', rows: 8, class: 'request-json', spellcheck: 'false',
      autocomplete: 'off' });
    editor.value = JSON.stringify({ op: 'wck.status', ids: '0-2' }, null, 2);
    const show = h('button', { type: 'button', onclick: dryRun }, 'Show dry run');
    const run = h('button', { type: 'button', class: 'secondary', onclick: runIt }, 'Run it');
    const stop = h('button', { type: 'button', class: 'danger', hidden: true, onclick: () => handle?.stop() }, 'Stop run');
    let handle = null;
    const status = h('p', { role: 'status', 'aria-live': 'polite', class: 'summary' });
    const effect = h('dd', { 'data-field': 'effect' }, '–');
    const confirm = h('dd', { 'data-field': 'confirm' }, '–');
    const steps = h('dd', { 'data-field': 'steps' }, '–');
    const frames = h('pre', { class: 'frames', 'aria-label': 'Dry run: bytes and frames', tabindex: 0 });
    const report = h('pre', { class: 'report', 'aria-label': 'Report', tabindex: 0, hidden: true });
    const progress = h('progress', { 'aria-label': 'Run progress', max: 1, value: 0, hidden: true });

    element.append(
      h('h2', {}, 'Preview'),
      h('p', { class: 'lead' }, 'Any request, as ', h('code', {}, 'robobus run'), ' reads it, and its dry run: ',
        'the exact packets or frames it would send (', h('code', {}, '--dry-run'), '), what it needs confirmed ',
        'and what it does to a device. Nothing is sent until "Run it".'),
      h('div', { class: 'columns' },
        h('section', { class: 'card', 'aria-labelledby': 'preview-req-title' },
          h('h3', { id: 'preview-req-title' }, 'Request'),
          h('div', { class: 'field' }, h('label', { for: 'preview-request' }, 'Request (JSON)'), editor),
          h('p', { class: 'hint' }, 'For example ', h('code', {}, '{"op": "whj.move", "joint": 1, "degrees": 30}'),
            ' (', h('code', {}, 'robobus schema request'), ' lists every request).'),
          h('div', { class: 'row' }, show, run, stop, h('span', { class: 'progress' }, progress)),
          status,
          report),
        h('section', { class: 'card', 'aria-labelledby': 'preview-plan-title' },
          h('h3', { id: 'preview-plan-title' }, 'Dry run'),
          h('dl', { class: 'plan-facts' },
            h('dt', {}, 'Effect'), effect,
            h('dt', {}, 'Confirmation'), confirm,
            h('dt', {}, 'Steps'), steps),
          h('h4', {}, 'Bytes and frames it sends'),
          frames)));

    function say(text, kind = 'info') {
      status.textContent = text;
      status.className = `summary ${kind === 'error' ? 'fail' : kind === 'ok' ? 'ok' : ''}`;
    }

    /** The editor's request, or null (the error shown and the caret on it). */
    function request() {
      try {
        const r = JSON.parse(editor.value);
        if (r == null || typeof r !== 'object' || Array.isArray(r)) throw new Error('a request is one JSON object with an "op"');
        return r;
      } catch (e) {
        const at = jsonErrorAt(editor.value, e.message);
        say(`Not a request${at ? ` (line ${at.line}, column ${at.column})` : ''}: ${e.message}`, 'error');
        if (at) {
          const lines = editor.value.split('\n');
          const off = lines.slice(0, at.line - 1).reduce((n, l) => n + l.length + 1, 0) + at.column - 1;
          editor.focus();
          editor.setSelectionRange(off, off + 1);
        }
        return null;
      }
    }

    async function dryRun() {
      const r = request();
      if (!r) return;
      say('Planning…');
      report.hidden = true;
      try {
        const p = await studio.plan(r);
        effect.textContent = EFFECTS[p.effect] ?? p.effect ?? '–';
        effect.dataset.value = p.effect ?? '';
        const cls = p.confirm ?? (p.ask == null ? 'none' : 'yes');
        confirm.textContent = p.ask == null ? 'none: runs without asking' : `${cls}: ${p.ask}`;
        confirm.dataset.value = cls;
        const n = p.steps?.length ?? 0;
        steps.textContent = `${n}${p.truncated ? ' (the first ones of a streamed plan)' : ''}`;
        frames.textContent = p.text || '(nothing is sent)';
        say(`Dry run of ${r.op}: nothing was sent.`, 'ok');
      } catch (e) {
        effect.textContent = confirm.textContent = steps.textContent = '–';
        frames.textContent = '';
        say(`Dry run refused${e?.kind ? ` (${e.kind})` : ''}: ${e?.message ?? e}`, 'error');
      }
    }

    async function runIt() {
      const r = request();
      if (!r) return;
      say(`Running ${r.op}…`);
      const long = LONG.has(r.op);
      progress.hidden = !long;
      progress.value = 0;
      try {
        const rep = await studio.confirmAndRun(r, {
          long,
          onProgress: (p) => {
            if (p.total) progress.max = p.total;
            progress.value = p.done ?? 0;
          },
          onStart: (hd) => {
            handle = hd;
            stop.hidden = false;
          },
        });
        if (rep == null) return say('Cancelled; nothing was sent.');
        report.hidden = false;
        report.textContent = JSON.stringify(rep, null, 2);
        say(rep.failed ? `${r.op} ran; a device failed (${rep.failed}).` : `${r.op} ran.`, rep.failed ? 'error' : 'ok');
      } catch (e) {
        say(`${r.op} failed${e?.kind ? ` (${e.kind})` : ''}: ${e?.message ?? e}`, 'error');
      } finally {
        progress.hidden = true;
        stop.hidden = true;
        handle = null;
      }
    }

    studio.setPreviewHandler?.((req) => {
      editor.value = JSON.stringify(req, null, 2);
      dryRun();
    });
  },
};
