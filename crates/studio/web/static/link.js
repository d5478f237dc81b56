// The page's side of its link to the studio server: a WebSocket that lives in a dedicated
// worker (link-worker.js) with the heartbeat, so that an armed page keeps beating while its
// main thread is busy. It behaves as a WebSocket for core.js (`readyState`, `send`, `close`,
// the events `message` and `close`) and adds `beat(on)`, and the event `withheld` when the
// worker stopped beating because this page's main thread did not answer its pings in time.
// A worker that stops pinging while it should beat (it died or hangs) is taken as a closed
// link: the worker is ended, which closes its WebSocket, and the page reconnects.

/** How long a beating worker may stay silent before the link counts as closed, ms. */
const WORKER_SILENT_MS = 3000;
/** How often the page looks at it, ms. */
const WATCH_MS = 500;

export class Link extends EventTarget {
  static CONNECTING = 0;
  static OPEN = 1;
  static CLOSING = 2;
  static CLOSED = 3;

  /** Open the WebSocket at `url` in a new worker. */
  constructor(url) {
    super();
    this.readyState = Link.CONNECTING;
    this.worker = new Worker(new URL("./link-worker.js", import.meta.url), { type: "module", name: "robobus-link" });
    this.beating = false;
    this.lastFromWorker = performance.now();
    this.lastWatch = performance.now();
    this.watch = setInterval(() => this.#watch(), WATCH_MS);
    this.worker.addEventListener("message", (e) => this.#fromWorker(e.data));
    this.worker.addEventListener("error", (e) => {
      console.warn("the studio's link worker failed", e.message ?? e);
      this.#closed(1006, "the link worker failed");
    });
    this.worker.postMessage({ cmd: "open", url });
  }

  #watch() {
    const now = performance.now();
    // After this thread itself stalled, the worker's messages may still wait in its queue.
    const stalled = now - this.lastWatch > 3 * WATCH_MS;
    this.lastWatch = now;
    if (stalled || !this.beating || this.readyState !== Link.OPEN) return;
    if (now - this.lastFromWorker > WORKER_SILENT_MS) this.#closed(1006, "the link worker stopped answering");
  }

  #fromWorker(m) {
    this.lastFromWorker = performance.now();
    switch (m?.ev) {
      case "open":
        this.readyState = Link.OPEN;
        this.dispatchEvent(new Event("open"));
        break;
      case "message":
        this.dispatchEvent(new MessageEvent("message", { data: m.data }));
        break;
      case "close":
        this.#closed(m.code, m.reason);
        break;
      case "ping":
        this.worker?.postMessage({ cmd: "alive" });
        break;
      case "withheld":
        this.dispatchEvent(new CustomEvent("withheld", { detail: { silentMs: m.silentMs } }));
        break;
      default:
        break;
    }
  }

  #closed(code, reason) {
    if (this.readyState === Link.CLOSED) return;
    this.readyState = Link.CLOSED;
    clearInterval(this.watch);
    this.worker?.terminate();
    this.worker = null;
    this.dispatchEvent(new CloseEvent("close", { code: code ?? 1006, reason: reason ?? "" }));
  }

  /** Send a text message (dropped unless open, as core.js checks first). */
  send(data) {
    if (this.readyState === Link.OPEN) this.worker.postMessage({ cmd: "send", data });
  }

  /** Close the WebSocket; the `close` event follows. */
  close() {
    if (this.readyState >= Link.CLOSING) return;
    this.readyState = Link.CLOSING;
    this.worker.postMessage({ cmd: "close" });
  }

  /** Start (armed) or stop the heartbeat: the worker sends it every 100 ms while this page is alive. */
  beat(on) {
    this.beating = !!on;
    this.lastFromWorker = performance.now();
    this.worker?.postMessage({ cmd: "beat", on: !!on });
  }
}
