// Preview: any request as JSON, its dry run (the exact bytes / frames `--dry-run` prints,
// what it needs confirmed, its effect) and, on demand, the run itself, both through the
// commissioning panels' flow (`flow.js`). Other panels open it with a request filled in
// (`studio.preview(request)`).

import { h, panelStyles } from '../ui.js';
import { createFlow } from './flow.js';

// Requests that report progress while they run (their report comes at the end).
const LONG = new Set(['whj.wave', 'whj.move', 'whj.speed', 'whj.current', 'wck.play', 'wck.teach',
  'wck.wheel', 'wck.scan', 'whj.scan']);

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
    // The commissioning panels' flow: its dry run (effect, confirmation, bytes and frames),
    // status line, progress, Stop and report; Preview only reads the request from the editor.
    const flow = createFlow(studio, { name: 'Preview' });
    const show = h('button', { type: 'button', onclick: dryRun }, 'Show dry run');
    const run = h('button', { type: 'button', class: 'secondary', onclick: runIt }, 'Run it');

    element.append(
      h('h2', {}, 'Preview'),
      h('p', { class: 'lead' }, 'Any request, as ', h('code', {}, 'robobus run'), ' reads it, and its dry run: ',
        'the exact packets or frames it would send (', h('code', {}, '--dry-run'), '), what it needs confirmed ',
        'and what it does to a device. Nothing is sent until "Run it".'),
      h('section', { class: 'card', 'aria-labelledby': 'preview-req-title' },
        h('h3', { id: 'preview-req-title' }, 'Request'),
        h('div', { class: 'field' }, h('label', { for: 'preview-request' }, 'Request (JSON)'), editor),
        h('p', { class: 'hint' }, 'For example ', h('code', {}, '{"op": "whj.move", "joint": 1, "degrees": 30}'),
          ' (', h('code', {}, 'robobus schema request'), ' lists every request).'),
        h('div', { class: 'row' }, show, run),
        flow.element));

    /** The editor's request, or null (the error shown and the caret on it). */
    function request() {
      try {
        const r = JSON.parse(editor.value);
        if (r == null || typeof r !== 'object' || Array.isArray(r)) throw new Error('a request is one JSON object with an "op"');
        return r;
      } catch (e) {
        const at = jsonErrorAt(editor.value, e.message);
        flow.say(`Not a request${at ? ` (line ${at.line}, column ${at.column})` : ''}: ${e.message}`, 'error');
        if (at) {
          const lines = editor.value.split('\n');
          const off = lines.slice(0, at.line - 1).reduce((n, l) => n + l.length + 1, 0) + at.column - 1;
          editor.focus();
          editor.setSelectionRange(off, off + 1);
        }
        return null;
      }
    }

    function dryRun() {
      const r = request();
      if (r) flow.dryRun(r);
    }

    async function runIt() {
      const r = request();
      if (!r) return;
      run.disabled = true;
      try {
        await flow.run(r, { long: LONG.has(r.op) });
      } finally {
        run.disabled = false;
      }
    }

    studio.setPreviewHandler?.((req) => {
      editor.value = JSON.stringify(req, null, 2);
      dryRun();
    });
  },
};
