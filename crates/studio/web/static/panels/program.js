// Program: the wCK self-running motion program (manual section 3-11) in its text form:
// check it (`wck.program.check`: errors at line and column), upload it
// (`wck.program.upload`, EEPROM, confirmed), download and verify it
// (`wck.program.download`).
//
// The wCK protocol reads back only a program's instruction count (A-1 (25) Motion Data
// Read replies the count, not the instructions), so Download shows the count and Verify
// compares counts. There is no "run" command either: a servo runs its stored program by
// itself while it holds one (an upload restarts it), so the panel has no Run button.

import { devicePicker, h, panelStyles, errorPosition } from '../ui.js';

const EXAMPLE = `# swing between two positions, three times
move 82 torque 0
delay 500ms
move 172 torque 0
delay 500ms
repeat 3
end
`;

const FORMAT = `One instruction a line, at most 8; # starts a comment:
  none                           no operation
  move <0..254> torque <0..4>    position move (torque 0 = max)
  motion passive | motion break
  wheel ccw|cw <0..15>
  delay <0..4095>ms
  output <0..3>                  digital outputs
  if pos|adc <op> <0..254>       op: == > < >= <=; false skips the next line
  repeat <1..254> | repeat forever
  end`;

/** Selects the token at `line`:`column` (1-based, columns in characters) of a textarea. */
export function moveCaret(textarea, line, column) {
  const lines = textarea.value.split('\n');
  let offset = 0;
  for (let i = 0; i < line - 1 && i < lines.length; i++) offset += lines[i].length + 1;
  const text = lines[Math.min(line, lines.length) - 1] ?? '';
  const chars = Array.from(text);
  const before = chars.slice(0, column - 1).join('').length;
  let end = before;
  while (end < text.length && !/\s/.test(text[end])) end++;
  textarea.focus();
  textarea.setSelectionRange(offset + before, offset + Math.max(end, before));
  // Scroll the line into view: about one line height per line.
  const lh = parseFloat(getComputedStyle(textarea).lineHeight) || 18;
  textarea.scrollTop = Math.max(0, (line - 3) * lh);
}

export default {
  id: 'program',
  title: 'Program',
  mount(element, studio) {
    panelStyles('program');
    const picker = devicePicker(studio, { families: ['wck'], label: 'Servo' });
    const editor = h('textarea', { id: 'program-editor', name: 'program', rows: 9, spellcheck: 'false',
      autocomplete: 'off', class: 'program-code', 'aria-describedby': 'program-format' });
    editor.value = EXAMPLE;
    const editorLabel = h('label', { for: 'program-editor' }, 'Motion program');
    const format = h('pre', { id: 'program-format', class: 'hint program-format' }, FORMAT);

    const check = h('button', { type: 'button', class: 'secondary', onclick: doCheck }, 'Check');
    const upload = h('button', { type: 'button', onclick: doUpload }, 'Upload');
    const download = h('button', { type: 'button', class: 'secondary', onclick: doDownload }, 'Download');
    const verify = h('button', { type: 'button', class: 'secondary', onclick: doVerify }, 'Verify');
    const dry = h('button', { type: 'button', class: 'preview-btn', 'aria-label': 'Show dry run of the upload',
      onclick: () => studio.preview(uploadRequest()) }, 'Preview');
    const gate = h('p', { class: 'hint', role: 'note' });
    const status = h('p', { role: 'status', 'aria-live': 'polite', class: 'summary' });
    const details = h('div', { class: 'program-details' });

    element.append(
      h('h2', {}, 'Program'),
      h('p', { class: 'lead' }, 'A wCK servo\'s self-running motion program (manual section 3-11): up to 8 instructions ',
        'stored in its EEPROM. A servo runs its stored program by itself while it holds one: an upload starts it, ',
        'an empty program switches it off. The protocol reads back only the instruction count, so Download and ',
        'Verify work on the count.'),
      h('div', { class: 'columns' },
        h('section', { class: 'card', 'aria-labelledby': 'program-title' },
          h('h3', { id: 'program-title' }, 'Editor'),
          h('div', { class: 'row' }, picker.element),
          h('div', { class: 'field' }, editorLabel, editor),
          h('div', { class: 'row' }, check, h('span', { class: 'action' }, upload, dry), download, verify),
          gate,
          format),
        h('section', { class: 'card', 'aria-labelledby': 'program-result' },
          h('h3', { id: 'program-result' }, 'Result'),
          status, details)));

    function sel() {
      const d = picker.get();
      return { id: d?.id ?? 0, ...(d?.bus && studio.buses('wck').length > 1 ? { bus: d.bus } : {}) };
    }
    function uploadRequest() {
      return { op: 'wck.program.upload', ...sel(), program: editor.value };
    }
    function say(text, kind = 'info') {
      status.textContent = text;
      status.className = `summary ${kind === 'error' ? 'fail' : kind === 'ok' ? 'ok' : ''}`;
      delete status.dataset.verify;
    }
    function fail(what, e) {
      const pos = errorPosition(e?.message);
      if (pos && e?.kind === 'bad-input') {
        say(`${what}: line ${pos.line}, column ${pos.column}: ${pos.message}`, 'error');
        moveCaret(editor, pos.line, pos.column);
      } else {
        say(`${what} failed${e?.kind ? ` (${e.kind})` : ''}: ${e?.message ?? e}`, 'error');
      }
    }
    function update() {
      const s = studio.state ?? {};
      // The servo starts an uploaded program at once: an upload moves it, so it needs arming.
      upload.disabled = !s.controller || !s.armed || s.readOnly;
      gate.textContent = s.readOnly ? 'Read-only studio: uploads are not served.'
        : !s.controller ? 'Take control and arm to upload (the servo starts the program at once).'
        : !s.armed ? 'Arm to upload: the servo starts the program at once.' : '';
    }
    studio.on('control', update);
    studio.on('state', update);
    update();

    /** Checks the editor's program; the summary, or null (the error shown). */
    async function checked() {
      const r = await studio.run({ op: 'wck.program.check', program: editor.value, id: sel().id });
      return r.summary;
    }

    function showInstructions(summary) {
      const rows = summary.instructions ?? [];
      const hex = (n) => n.toString(16).toUpperCase().padStart(2, '0');
      details.replaceChildren(
        h('table', { class: 'instructions' },
          h('caption', {}, `${rows.length} instruction${rows.length === 1 ? '' : 's'} (at most 8)`),
          h('thead', {}, h('tr', {}, ['#', 'Instruction', 'Command byte', 'Data byte'].map((c) => h('th', { scope: 'col' }, c)))),
          h('tbody', {}, rows.map((ins, i) => h('tr', {},
            h('td', { class: 'num' }, String(i + 1)), h('td', {}, h('code', {}, ins.text)),
            h('td', { class: 'num' }, `0x${hex(ins.command)}`), h('td', { class: 'num' }, String(ins.data)))))),
        h('p', {}, `Upload packet for servo ${summary.upload_packet?.id}: `,
          h('code', { class: 'packet', 'aria-label': 'Upload packet' }, summary.upload_packet?.hex ?? '')));
    }

    async function doCheck() {
      details.replaceChildren();
      say('Checking…');
      try {
        const s = await checked();
        say(`OK: ${s.instructions.length} instruction${s.instructions.length === 1 ? '' : 's'}.`, 'ok');
        showInstructions(s);
      } catch (e) {
        fail('Check', e);
      }
    }

    async function doUpload() {
      details.replaceChildren();
      say('Uploading…');
      try {
        const r = await studio.confirmAndRun(uploadRequest());
        if (r == null) return say('Upload cancelled; nothing was sent.');
        const row = r.results?.[0] ?? {};
        if (row.kind) return say(`Upload failed (${row.kind}): ${row.error}`, 'error');
        say(`Uploaded: servo ${row.id} holds ${row.instructions} instruction${row.instructions === 1 ? '' : 's'} (read back).`, 'ok');
      } catch (e) {
        fail('Upload', e);
      }
    }

    /** The count the servo holds (throws on a failure). */
    async function stored() {
      const r = await studio.run({ op: 'wck.program.download', ...sel() });
      const row = r.results?.[0] ?? {};
      if (row.kind) throw Object.assign(new Error(row.error), { kind: row.kind });
      return row.instructions;
    }

    async function doDownload() {
      details.replaceChildren();
      say('Downloading…');
      try {
        const n = await stored();
        say(`Servo ${sel().id} holds a program of ${n} instruction${n === 1 ? '' : 's'}` +
          `${n === 0 ? ' (self-running motion off)' : ''}. The protocol returns the count only; the editor is unchanged.`, 'ok');
      } catch (e) {
        fail('Download', e);
      }
    }

    async function doVerify() {
      details.replaceChildren();
      say('Verifying…');
      let mine;
      try {
        mine = (await checked()).instructions.length;
      } catch (e) {
        return fail('Verify (the editor does not check)', e);
      }
      try {
        const theirs = await stored();
        const same = theirs === mine;
        say(`${same ? 'Equal' : 'Different'}: servo ${sel().id} holds ${theirs} instruction${theirs === 1 ? '' : 's'}, ` +
          `the editor has ${mine} (the protocol compares counts only).`, same ? 'ok' : 'error');
        status.dataset.verify = same ? 'equal' : 'different';
      } catch (e) {
        fail('Verify', e);
      }
    }
  },
};
