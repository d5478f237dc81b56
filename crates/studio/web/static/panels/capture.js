// Capture: the session's traffic per bus (GET /api/capture), each downloadable as the file
// `robobus replay FILE` decodes (GET /api/capture/{bus}).

import { h } from '../ui.js';

function size(bytes) {
  if (bytes < 1024) return `${bytes} B`;
  if (bytes < 1 << 20) return `${(bytes / 1024).toFixed(1)} KiB`;
  return `${(bytes / (1 << 20)).toFixed(1)} MiB`;
}

/** The name a capture is saved under: BUS.log (candump's own extension) or BUS.hex.txt. */
function fileName(bus, format) {
  return `${bus.replace(/[^\w.-]+/g, '_')}${format === 'candump' ? '.log' : '.hex.txt'}`;
}

export default {
  id: 'capture',
  title: 'Capture',
  mount(element, studio) {
    const refresh = h('button', { type: 'button', class: 'secondary', onclick: list }, 'Refresh');
    const status = h('p', { role: 'status', 'aria-live': 'polite', class: 'hint' });
    const body = h('tbody');
    const table = h('table', { class: 'captures' },
      h('caption', {}, 'Capture files'),
      h('thead', {}, h('tr', {}, ['Bus', 'Format', 'Size', 'File'].map((c) => h('th', { scope: 'col' }, c)))),
      body);

    element.append(
      h('h2', {}, 'Capture'),
      h('p', { class: 'lead' }, 'Every byte and frame this session sent and received, per bus: ',
        'wCK buses as a timestamped hex log, WHJ buses as a candump log. Decode a file with ',
        h('code', {}, 'robobus replay FILE'), '.'),
      h('section', { class: 'card', 'aria-label': 'Capture files' },
        h('div', { class: 'row' }, refresh, status),
        table));

    async function download(ev, bus, format) {
      ev.preventDefault();
      try {
        // Through the studio, which adds the token header a plain link could not carry.
        const blob = await studio.blob(`/api/capture/${encodeURIComponent(bus)}`);
        const a = h('a', { href: URL.createObjectURL(blob), download: fileName(bus, format) });
        document.body.append(a);
        a.click();
        a.remove();
        setTimeout(() => URL.revokeObjectURL(a.href), 10000);
        status.textContent = `Downloaded the capture of ${bus} (${size(blob.size)}).`;
      } catch (e) {
        status.textContent = `Download of ${bus} failed: ${e.message}`;
      }
    }

    async function list() {
      if (studio.info && studio.info.capture === false) {
        body.replaceChildren();
        status.textContent = 'This session records no capture.';
        return;
      }
      status.textContent = 'Loading…';
      try {
        const files = await studio.get('/api/capture');
        body.replaceChildren(...files.map((f) => h('tr', { 'data-bus': f.bus },
          h('td', {}, f.bus),
          h('td', {}, f.format),
          h('td', { class: 'num', title: `${f.bytes} bytes` }, size(f.bytes)),
          h('td', {}, h('a', { href: `/api/capture/${encodeURIComponent(f.bus)}`,
            onclick: (ev) => download(ev, f.bus, f.format) }, `Download capture of ${f.bus}`)))));
        if (!files.length) body.append(h('tr', {}, h('td', { colspan: 4, class: 'hint' }, 'No traffic captured yet.')));
        status.textContent = `${files.length} capture file${files.length === 1 ? '' : 's'}, as of ${new Date().toLocaleTimeString()}.`;
      } catch (e) {
        status.textContent = `Could not list the captures: ${e.message}`;
      }
    }
    // The shell sends `studio:show` after mounting and on every return to the tab.
    element.addEventListener('studio:show', list);
  },
};
