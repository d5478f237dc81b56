// The page's link to the studio server, in a dedicated worker: the WebSocket and the
// heartbeat of an armed page (link.js is the page's side, docs/studio.md says why).
//
// A worker's timers run whatever the page's main thread is doing (mounting a panel's
// charts, a long layout on a busy machine), so the heartbeat keeps its 100 ms while the page
// is busy. It is still a dead man's switch: while beating, it asks the page's main thread
// every quarter second whether it is alive (a message the thread answers when it runs its
// events, whatever its timers' throttling), and when no answer came for MAIN_ALLOWANCE_MS
// it stops beating, so a page that hangs loses control as one that closes does.
//
// From the page: {cmd: "open", url} · {cmd: "send", data} · {cmd: "close"} ·
// {cmd: "beat", on} · {cmd: "alive"} (the answer to a ping).
// To the page: {ev: "open"} · {ev: "message", data} · {ev: "close", code, reason} ·
// {ev: "ping"} · {ev: "withheld", silentMs} (the beat stopped: the page was silent that long).

const BEAT_MS = 100;
const PING_MS = 250;
const MAIN_ALLOWANCE_MS = 2000;
const HEARTBEAT = JSON.stringify({ type: "heartbeat" });

let ws = null;
let beating = false;
let lastAlive = performance.now();
let withheld = false;
let timer = null;
let pinger = null;

function beat() {
  if (!beating || !ws || ws.readyState !== WebSocket.OPEN) return;
  const silent = performance.now() - lastAlive;
  if (silent > MAIN_ALLOWANCE_MS) {
    if (!withheld) {
      withheld = true;
      postMessage({ ev: "withheld", silentMs: Math.round(silent) });
    }
    return;
  }
  withheld = false;
  ws.send(HEARTBEAT);
}

function setBeating(on) {
  beating = on;
  if (on && !timer) {
    timer = setInterval(beat, BEAT_MS);
    pinger = setInterval(() => postMessage({ ev: "ping" }), PING_MS);
    beat();
  } else if (!on && timer) {
    clearInterval(timer);
    clearInterval(pinger);
    timer = null;
    pinger = null;
  }
}

function open(url) {
  const socket = new WebSocket(url);
  ws = socket;
  socket.addEventListener("open", () => postMessage({ ev: "open" }));
  socket.addEventListener("message", (e) => postMessage({ ev: "message", data: e.data }));
  socket.addEventListener("close", (e) => {
    setBeating(false);
    postMessage({ ev: "close", code: e.code, reason: e.reason });
  });
}

addEventListener("message", (e) => {
  const m = e.data;
  switch (m?.cmd) {
    case "open":
      lastAlive = performance.now();
      open(m.url);
      break;
    case "send":
      if (ws?.readyState === WebSocket.OPEN) ws.send(m.data);
      break;
    case "close":
      setBeating(false);
      ws?.close();
      break;
    case "beat":
      lastAlive = performance.now();
      setBeating(!!m.on);
      break;
    case "alive":
      lastAlive = performance.now();
      break;
    default:
      break;
  }
});
