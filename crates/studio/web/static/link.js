// The page's side of its link to the studio server: a WebSocket that lives in a dedicated
// worker (link-worker.js) with the heartbeat, so that an armed page keeps beating while its
// main thread is busy. It behaves as a WebSocket for core.js (`readyState`, `send`, `close`,
// the events `message` and `close`) and adds `beat(on)`, and the event `withheld` when the
// worker stopped beating because this page's main thread did not answer its pings in time.

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
    this.worker.addEventListener("message", (e) => this.#fromWorker(e.data));
    this.worker.addEventListener("error", (e) => {
      console.warn("the studio's link worker failed", e.message ?? e);
      this.#closed(1006, "the link worker failed");
    });
    this.worker.postMessage({ cmd: "open", url });
  }

  #fromWorker(m) {
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
    this.worker?.postMessage({ cmd: "beat", on: !!on });
  }
}
