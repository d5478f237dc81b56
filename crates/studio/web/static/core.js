// The studio's core: one `Studio` per page, shared by every panel.
//
// It owns the HTTP calls (`run`, `plan`), the WebSocket (`runLong`, `subscribe`, `jog`,
// control and arming, the heartbeat), the confirmation dialog, the toasts and the list of
// known devices. The contract it speaks is docs/studio.md. The WebSocket and the heartbeat
// live in a worker (link.js), so that a busy page stays armed.

import { Link } from "./link.js";

/** The HTTP status of each error kind (docs/studio.md), for errors that come over the WebSocket. */
const KIND_STATUS = {
  "bad-input": 400,
  refused: 409,
  "no-device": 504,
  device: 502,
  link: 502,
  interrupted: 499,
  "not-available": 501,
};

/** The kind an HTTP error status stands for when its body names none. */
function kindOfStatus(status) {
  if (status === 401) return "not-authorised";
  if (status === 403) return "forbidden";
  if (status === 429) return "rate-limited";
  for (const [kind, s] of Object.entries(KIND_STATUS)) if (s === status) return kind;
  return "link";
}

/** A request the server refused or that failed: `kind` as in docs/studio.md, `status` its HTTP status. */
export class StudioError extends Error {
  constructor(kind, message, status) {
    super(message);
    this.name = "StudioError";
    this.kind = kind;
    this.status = status ?? KIND_STATUS[kind] ?? 0;
  }
}

/** The message of any error, naming its kind when it has one. */
export function describeError(err) {
  if (err instanceof StudioError) return `${err.kind}: ${err.message}`;
  return err?.message ?? String(err);
}

const JOG_TIMEOUT_MS = 2000;
/** The messages that carry the control secret (the server refuses them without it). */
const PROVES_CONTROL = new Set(["arm", "run", "jog"]);
const RECONNECT_MS = [250, 500, 1000, 2000, 4000];

export class Studio {
  /** Connect to the server this page came from: /api/info, then the WebSocket, then take control. */
  static async connect() {
    const match = /(?:^#|&)token=([^&]*)/.exec(location.hash);
    const studio = new Studio(match ? decodeURIComponent(match[1]) : null);
    studio.info = await studio.#get("/api/info");
    for (const family of ["wck", "whj"]) {
      studio.devices[family] = (studio.info.robot ?? [])
        .filter((r) => r.family === family)
        .map((r) => ({ bus: r.bus, id: r.id, name: r.name }))
        .sort(byBusAndId);
    }
    studio.state.readOnly = !!studio.info.read_only;
    studio.state.simulated = !!studio.info.simulated;
    await studio.#open();
    return studio;
  }

  constructor(token) {
    this.token = token;
    this.info = null;
    /** The control secret the server gave this page's WebSocket while it controls (its `control` message): proof of control on every state-changing request. */
    this.secret = null;
    /** What this page may do; `connected` is false while the WebSocket is down. */
    this.state = {
      controller: false,
      armed: false,
      heldByOther: false,
      readOnly: false,
      simulated: false,
      connected: false,
    };
    /** The known devices per family, [{bus, id, name?, ...}]: the robot file's (the simulated robot's) until a Bus scan replaces a bus's list. */
    this.devices = { wck: [], whj: [] };
    this.showPanel = null; // set by the shell: async (panelId) => element
    this.ws = null;
    this.nextId = 1;
    this.pending = new Map(); // run id -> {resolve, reject, onProgress}
    this.jogs = new Map(); // jog id -> {resolve, reject, timer}
    this.streams = new Map(); // stream -> {request, rateHz, fps, onSample}
    this.handlers = new Map(); // message type -> Set of handlers
    this.heartbeat = false; // the link's worker beats (armed)
    /** Set while the page itself disarms (Disarm, the stop key, closing): any other disarm says why. */
    this.disarmAsked = false;
    /** The last `safe` message since arming, and whether the link withheld the beat (this page was silent). */
    this.lastSafe = null;
    this.withheldMs = null;
    this.previewHandler = null;
    this.pendingPreview = null;
    this.wantControl = true;
    this.closedByPage = false;
    this.reconnects = 0;
    addEventListener("pagehide", () => this.close());
  }

  // ---- HTTP ----

  #headers(json) {
    const h = {};
    if (json) h["Content-Type"] = "application/json";
    if (this.token) h.Authorization = `Bearer ${this.token}`;
    if (this.secret) h["X-Robobus-Control"] = this.secret;
    return h;
  }

  async #get(path) {
    return this.#answer(await fetch(path, { headers: this.#headers(false) }));
  }

  async #post(path, body) {
    let res;
    try {
      res = await fetch(path, {
        method: "POST",
        headers: this.#headers(true),
        body: JSON.stringify(body),
      });
    } catch (e) {
      throw new StudioError("link", `the studio server did not answer: ${e.message}`, 0);
    }
    return this.#answer(res);
  }

  async #answer(res) {
    const text = await res.text();
    let body = null;
    try {
      body = text ? JSON.parse(text) : null;
    } catch {
      body = null;
    }
    if (!res.ok) {
      const kind = body?.kind ?? kindOfStatus(res.status);
      const message = body?.message ?? (text || res.statusText || `HTTP ${res.status}`);
      throw new StudioError(kind, message, res.status);
    }
    return body;
  }

  /** Run one request (POST /api/run) and return its report. */
  run(request) {
    return this.#post("/api/run", request);
  }

  /**
   * The plan view of a request (POST /api/plan): the plan's fields (`steps`, `notes`,
   * `confirm`: the class, `truncated`, ...), `text`, `effect` and `ask` (what to ask the
   * user first, or null); nothing is sent.
   */
  plan(request) {
    return this.#post("/api/plan", request);
  }

  /** Fetch a path of the API with this page's credentials (GET), as JSON. */
  get(path) {
    return this.#get(path);
  }

  /** Fetch a path of the API with this page's credentials as a Blob (capture files). */
  async blob(path) {
    const res = await fetch(path, { headers: this.#headers(false) });
    if (!res.ok) await this.#answer(res);
    return res.blob();
  }

  /**
   * Run a request over the WebSocket with its progress. Returns `{id, promise, stop()}`:
   * the promise resolves to the report, or rejects with a StudioError (`interrupted` after
   * a stop).
   */
  runLong(request, onProgress) {
    const id = this.nextId++;
    let entry;
    const promise = new Promise((resolve, reject) => {
      entry = { resolve, reject, onProgress };
    });
    if (!this.#send({ type: "run", id, request })) {
      entry.reject(new StudioError("link", "not connected to the studio server", 0));
    } else {
      this.pending.set(id, entry);
    }
    return { id, promise, stop: () => this.#send({ type: "stop", id }) };
  }

  /**
   * Plan a request; when it needs a confirmation, ask for it in a modal dialog that names
   * what will be written. Runs the request (with `confirm: true` when confirmed) and
   * returns its report, or null when the user cancelled.
   * Options: `long` (run over the WebSocket), `onProgress`, `onStart(handle)` (the runLong
   * handle, to stop it).
   */
  async confirmAndRun(request, { long = false, onProgress, onStart } = {}) {
    const plan = await this.plan(request);
    let req = request;
    if (plan.ask) {
      const ok = await this.#confirmDialog(request, plan);
      if (!ok) return null;
      req = { ...request, confirm: true };
    }
    if (long) {
      const handle = this.runLong(req, onProgress);
      onStart?.(handle);
      return handle.promise;
    }
    return this.run(req);
  }

  #confirmDialog(request, plan) {
    return new Promise((resolve) => {
      const dlg = document.createElement("dialog");
      dlg.className = "confirm";
      dlg.setAttribute("aria-labelledby", "confirm-title");
      dlg.setAttribute("aria-describedby", "confirm-what");
      const title = el("h2", { id: "confirm-title" }, "Confirm a permanent write");
      const what = el("p", { id: "confirm-what" }, plan.ask);
      const target = el("p", { className: "confirm-request" }, describeRequest(request));
      const frames = el("details", {}, [
        el("summary", {}, "What will be sent"),
        el("pre", {}, plan.text ?? ""),
      ]);
      const cancel = el("button", { type: "button", className: "secondary" }, "Cancel");
      const confirm = el("button", { type: "button", className: "danger" }, "Confirm");
      const done = (ok) => {
        dlg.close();
        dlg.remove();
        resolve(ok);
      };
      cancel.addEventListener("click", () => done(false));
      confirm.addEventListener("click", () => done(true));
      dlg.addEventListener("cancel", (e) => {
        e.preventDefault();
        done(false);
      });
      dlg.append(title, what, target, frames, el("div", { className: "buttons" }, [cancel, confirm]));
      document.body.append(dlg);
      dlg.showModal();
      cancel.focus();
    });
  }

  // ---- WebSocket ----

  #wsUrl() {
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    const q = this.token ? `?token=${encodeURIComponent(this.token)}` : "";
    return `${proto}//${location.host}/api/ws${q}`;
  }

  #open() {
    return new Promise((resolve, reject) => {
      const ws = new Link(this.#wsUrl());
      this.ws = ws;
      ws.addEventListener("withheld", (e) => {
        if (this.ws === ws) this.withheldMs = e.detail.silentMs;
      });
      let hello = false;
      ws.addEventListener("message", (ev) => {
        let msg;
        try {
          msg = JSON.parse(ev.data);
        } catch {
          return;
        }
        if (msg.type === "control") this.secret = msg.secret ?? null;
        if (msg.type === "hello") {
          hello = true;
          this.secret = null;
          this.state.readOnly = !!msg.read_only;
          this.state.simulated = !!msg.simulated;
          this.state.connected = true;
          this.reconnects = 0;
          if (this.wantControl && !this.state.readOnly) this.#send({ type: "take-control" });
          for (const [stream, s] of this.streams) this.#sendSubscribe(stream, s);
          this.#emit("state", this.state);
          resolve();
          return;
        }
        this.#dispatch(msg);
      });
      ws.addEventListener("close", () => {
        if (this.ws !== ws) return;
        this.secret = null;
        this.#lost();
        if (!hello) reject(new StudioError("link", "the studio's WebSocket closed before its hello", 0));
        if (!this.closedByPage) this.#reconnect();
      });
    });
  }

  #lost() {
    this.#stopHeartbeat();
    const wasArmed = this.state.armed;
    if (wasArmed && !this.closedByPage) {
      this.#disarmedBy("connection lost", "the connection to the studio server was lost (the server brings the devices to their safe state)");
    }
    Object.assign(this.state, { connected: false, controller: false, armed: false, heldByOther: false });
    const err = new StudioError("link", "the connection to the studio server was lost", 0);
    for (const p of this.pending.values()) p.reject(err);
    this.pending.clear();
    for (const j of this.jogs.values()) {
      clearTimeout(j.timer);
      j.reject(err);
    }
    this.jogs.clear();
    this.#emit("state", this.state);
  }

  #reconnect() {
    const delay = RECONNECT_MS[Math.min(this.reconnects, RECONNECT_MS.length - 1)];
    this.reconnects++;
    setTimeout(() => {
      if (this.closedByPage) return;
      this.#open().catch(() => {});
    }, delay);
  }

  /** Close the WebSocket (the page is going away). */
  close() {
    this.closedByPage = true;
    this.disarmAsked = true;
    this.#stopHeartbeat();
    this.ws?.close();
  }

  #send(msg) {
    if (!this.ws || this.ws.readyState !== Link.OPEN) return false;
    // What changes a device proves this page's control with its secret.
    if (this.secret && PROVES_CONTROL.has(msg.type)) msg = { ...msg, control: this.secret };
    this.ws.send(JSON.stringify(msg));
    return true;
  }

  #dispatch(msg) {
    switch (msg.type) {
      case "control": {
        const wasArmed = this.state.armed;
        Object.assign(this.state, {
          controller: !!msg.controller,
          armed: !!msg.armed,
          heldByOther: !!msg.held_by_other,
        });
        if (this.state.armed) this.#startHeartbeat();
        else this.#stopHeartbeat();
        if (wasArmed && !this.state.armed) this.#disarmedUnasked();
        this.#emit("control", msg);
        this.#emit("state", this.state);
        break;
      }
      case "safe":
        this.lastSafe = msg;
        this.#stopHeartbeat();
        this.#emit("safe", msg);
        break;
      case "telemetry": {
        const s = this.streams.get(msg.stream);
        if (s) {
          try {
            s.onSample(msg.sample, msg.skipped ?? 0);
          } catch (e) {
            console.warn("telemetry handler", e);
          }
        }
        this.#emit("telemetry", msg);
        break;
      }
      case "progress":
        this.pending.get(msg.id)?.onProgress?.(msg);
        break;
      case "report": {
        const p = this.pending.get(msg.id);
        if (p) {
          this.pending.delete(msg.id);
          p.resolve(msg.report);
        }
        break;
      }
      case "jogged": {
        const j = this.jogs.get(msg.id);
        if (j) {
          this.jogs.delete(msg.id);
          clearTimeout(j.timer);
          j.resolve(msg);
        }
        break;
      }
      case "error": {
        const err = new StudioError(msg.kind, msg.message);
        const p = msg.id != null && this.pending.get(msg.id);
        const j = msg.id != null && this.jogs.get(msg.id);
        if (p) {
          this.pending.delete(msg.id);
          p.reject(err);
        } else if (j) {
          this.jogs.delete(msg.id);
          clearTimeout(j.timer);
          j.reject(err);
        } else if (!this.#emit("error", msg)) {
          this.toast(err);
        }
        break;
      }
      case "target":
        this.#emit("target", msg);
        break;
      default:
        this.#emit(msg.type, msg);
    }
  }

  /** Listen to server messages (`control`, `safe`, `target`, `telemetry`, `error`) and `state`, `devices`. Returns the function that stops listening. */
  on(type, handler) {
    if (!this.handlers.has(type)) this.handlers.set(type, new Set());
    this.handlers.get(type).add(handler);
    return () => this.handlers.get(type)?.delete(handler);
  }

  #emit(type, msg) {
    const hs = this.handlers.get(type);
    if (!hs || hs.size === 0) return false;
    for (const h of [...hs]) {
      try {
        h(msg);
      } catch (e) {
        console.warn(`handler of ${type}`, e);
      }
    }
    return true;
  }

  // ---- control, arming, heartbeat ----

  takeControl() {
    this.wantControl = true;
    this.#send({ type: "take-control" });
  }

  releaseControl() {
    this.wantControl = false;
    this.#send({ type: "release-control" });
  }

  arm() {
    this.disarmAsked = false;
    this.lastSafe = null;
    this.withheldMs = null;
    if (this.#send({ type: "arm" })) this.#startHeartbeat();
    this.#emit("disarmed", null);
  }

  disarm() {
    this.disarmAsked = true;
    this.#send({ type: "disarm" });
    this.#stopHeartbeat();
  }

  /**
   * The stop key: stop every run of this page and disarm (the server stops every motion
   * and brings what moved to its safe state). Returns how many runs were asked to stop.
   */
  stopAll() {
    for (const id of this.pending.keys()) this.#send({ type: "stop", id });
    if (this.state.armed || this.heartbeat) this.disarm();
    return this.pending.size;
  }

  /** The heartbeat runs in the link's worker: it does not wait for this page's main thread. */
  #startHeartbeat() {
    if (this.heartbeat || !this.ws) return;
    this.heartbeat = true;
    this.ws.beat(true);
  }

  #stopHeartbeat() {
    if (!this.heartbeat) return;
    this.heartbeat = false;
    this.ws?.beat(false);
  }

  /** The page was disarmed without asking: say why (the shell shows it until the next Arm). */
  #disarmedUnasked() {
    if (this.disarmAsked) return;
    const reason = this.lastSafe?.reason ?? "disarmed by the server";
    let why;
    if (reason === "heartbeat lost" && this.withheldMs != null) {
      const tab = document.hidden ? "a tab in the background the browser paused" : "a frozen or overloaded tab";
      why = `this page did not respond for over ${(this.withheldMs / 1000).toFixed(1)} s (${tab}), so its heartbeat stopped`;
    } else if (reason === "heartbeat lost") {
      why = "the heartbeat did not reach the server in time (the network or the server was too slow)";
    } else {
      why = reason;
    }
    this.#disarmedBy(reason, why);
  }

  #disarmedBy(reason, why) {
    this.disarmAsked = true; // said once
    this.#emit("disarmed", { reason, why, unixMs: Date.now() });
  }

  // ---- telemetry and jogs ----

  /**
   * Sample a reading request on the server at `rateHz`, delivered at most `fps` times a
   * second to `onSample(sample, skipped)`. Stream names are the page's own: one
   * subscription per name (a second one replaces the first). Returns the unsubscribe
   * function. Subscriptions are renewed after a reconnect.
   */
  subscribe(stream, request, rateHz, fps, onSample) {
    const s = { request, rateHz, fps, onSample };
    this.streams.set(stream, s);
    this.#sendSubscribe(stream, s);
    return () => {
      if (this.streams.get(stream) !== s) return;
      this.streams.delete(stream);
      this.#send({ type: "unsubscribe", stream });
    };
  }

  #sendSubscribe(stream, s) {
    this.#send({
      type: "subscribe",
      stream,
      request: s.request,
      rate_hz: s.rateHz,
      fps: s.fps ?? 30,
    });
  }

  /** One jog step toward `target` (wCK: steps 0..=254; WHJ: degrees). Resolves to the `jogged` message. */
  jog(family, bus, device, target) {
    const id = this.nextId++;
    return new Promise((resolve, reject) => {
      if (!this.#send({ type: "jog", id, family, bus: bus ?? null, device, target })) {
        reject(new StudioError("link", "not connected to the studio server", 0));
        return;
      }
      const timer = setTimeout(() => {
        this.jogs.delete(id);
        reject(new StudioError("link", "no answer to the jog", 0));
      }, JOG_TIMEOUT_MS);
      this.jogs.set(id, { resolve, reject, timer });
    });
  }

  // ---- devices ----

  /** The names of the buses of a family (`wck` / `whj`). */
  buses(family) {
    return (this.info?.[family] ?? []).map((b) => b.name);
  }

  /**
   * The known devices of a family, [{bus, id, name?}]: those of the last Bus scan, else the
   * robot file's (the simulated robot's) devices.
   */
  ids(family) {
    return this.devices[family] ?? [];
  }

  /** Record the devices a scan found on a bus (replacing that bus's earlier list) and tell the panels. */
  setDevices(family, bus, list) {
    const names = new Map(this.ids(family).map((d) => [`${d.bus}/${d.id}`, d.name]));
    const others = this.ids(family).filter((d) => d.bus !== bus);
    const found = list.map((d) => ({ ...d, bus, name: names.get(`${bus}/${d.id}`) }));
    this.devices[family] = [...others, ...found].sort(byBusAndId);
    this.#emit("devices", { family, devices: this.devices[family] });
  }

  // ---- page helpers ----

  /** Show a status message; `kind` is `info`, `ok` or `error` (an Error shows as an error naming its kind). */
  toast(message, kind = "info") {
    if (message instanceof Error) {
      kind = "error";
      message = describeError(message);
    }
    const region = toastRegion(kind === "error" ? "alert" : "status");
    const item = el("div", { className: `toast ${kind}` }, [el("span", {}, message)]);
    const dismiss = el("button", { type: "button", className: "link", ariaLabel: "Dismiss message" }, "×");
    dismiss.addEventListener("click", () => item.remove());
    item.append(dismiss);
    region.append(item);
    while (region.children.length > 4) region.firstElementChild.remove();
    setTimeout(() => item.remove(), kind === "error" ? 15000 : kind === "ok" ? 3000 : 6000);
  }

  /** Show a request's dry run in the Preview panel. */
  async preview(request) {
    this.pendingPreview = request;
    if (this.showPanel) await this.showPanel("preview");
    if (this.previewHandler && this.pendingPreview) {
      const r = this.pendingPreview;
      this.pendingPreview = null;
      this.previewHandler(r);
    }
  }

  /** The Preview panel registers the function that shows a request's dry run. */
  setPreviewHandler(fn) {
    this.previewHandler = fn;
    if (fn && this.pendingPreview) {
      const r = this.pendingPreview;
      this.pendingPreview = null;
      fn(r);
    }
  }
}

function byBusAndId(a, b) {
  return a.bus === b.bus ? a.id - b.id : a.bus < b.bus ? -1 : 1;
}

function toastRegion(role) {
  let region = document.getElementById(`toasts-${role}`);
  if (!region) {
    let box = document.getElementById("toasts");
    if (!box) {
      box = el("div", { id: "toasts" });
      document.body.append(box);
    }
    region = el("div", { id: `toasts-${role}` });
    region.setAttribute("role", role);
    region.setAttribute("aria-live", role === "alert" ? "assertive" : "polite");
    box.append(region);
  }
  return region;
}

/** A one-line description of a request: its operation and the devices it addresses. */
export function describeRequest(req) {
  const parts = [];
  for (const [k, v] of Object.entries(req)) {
    if (k === "op" || k === "confirm") continue;
    parts.push(`${k.replaceAll("_", " ")} ${Array.isArray(v) ? v.join(",") : v}`);
  }
  return parts.length ? `${req.op}: ${parts.join(", ")}` : req.op;
}

/** Make an element: `el("button", {type: "button", onclick}, "Text")`; props are set as properties (`dataset`, `ariaLabel` too). */
export function el(tag, props = {}, children = []) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(props)) {
    if (v === undefined || v === null) continue;
    if (k === "dataset") Object.assign(e.dataset, v);
    else if (k.startsWith("on") && typeof v === "function") e.addEventListener(k.slice(2), v);
    else if (k === "ariaLabel") e.setAttribute("aria-label", v);
    else if (k in e && !k.includes("-")) {
      try {
        e[k] = v;
      } catch {
        e.setAttribute(k, v); // a read-only property (`list`): its attribute
      }
    } else e.setAttribute(k, v === true ? "" : v);
  }
  for (const c of [].concat(children)) {
    if (c === null || c === undefined || c === false) continue;
    e.append(c instanceof Node ? c : String(c));
  }
  return e;
}
