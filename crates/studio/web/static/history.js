// The page's history: every known device's readings, recorded from the moment the page
// connects, whatever a panel draws (ticking a device in the Plot chooses what is drawn,
// not what is recorded). One ring per device, so memory is bounded however long the page
// stays open; one telemetry stream per bus (the station samples a bus once for every page
// and panel). It is also where the header learns which devices are silent.
//
// Targets: every position target a page commanded (the server's `target` messages: jogs,
// moves) and the signal a page asked of a wave, kept per device for the same time.
//
// Robot joints (the robot file's, by name, in its joint frame): while a `robot.play` of
// this page runs (Poses, Robot), `robot.sample` is recorded into a ring per joint and the
// trajectory's points are the joints' targets, from the tick its first point is due. A
// wCK keyframe scene (`wck.play`) gives its servos' targets the same way.

/** Seconds of readings kept per device (the Plot shows at most 60 s). */
export const KEEP_S = 65;
/** The sampling rates (Hz) per family unless a panel sets them (the Plot's rate controls). */
export const DEFAULT_RATES = { whj: 25, wck: 10 };
/** The most a ring holds: KEEP_S at the highest rate a panel offers. */
const MAX_RATE = 50;
/** The most target points and wave segments kept per device. */
const MAX_TARGETS = 4096;

const WCK_DEG_PER_STEP = 269 / 255; // wck.status: degrees = steps × 269 / 255

/** A device's key: `family|bus|id`. */
export function deviceKey(family, bus, id) {
  return `${family}|${bus}|${id}`;
}

/** A fixed-size ring of readings: time (ms since the epoch), position (deg), speed (rpm), current (mA). */
class Ring {
  constructor(cap) {
    this.cap = cap;
    this.t = new Float64Array(cap);
    this.pos = new Float64Array(cap);
    this.speed = new Float64Array(cap);
    this.current = new Float64Array(cap);
    this.n = 0;
    this.head = 0; // the next slot written
  }

  push(t, pos, speed, current) {
    const i = this.head;
    this.t[i] = t;
    this.pos[i] = pos ?? Number.NaN;
    this.speed[i] = speed ?? Number.NaN;
    this.current[i] = current ?? Number.NaN;
    this.head = (i + 1) % this.cap;
    if (this.n < this.cap) this.n++;
  }

  /** The readings since `tmin` (ms), oldest first: {t, pos, speed, current} arrays (null where missing). */
  since(tmin) {
    const out = { t: [], pos: [], speed: [], current: [] };
    const start = (this.head - this.n + this.cap) % this.cap;
    const nn = (v) => (Number.isNaN(v) ? null : v);
    for (let k = 0; k < this.n; k++) {
      const i = (start + k) % this.cap;
      if (this.t[i] < tmin) continue;
      out.t.push(this.t[i]);
      out.pos.push(nn(this.pos[i]));
      out.speed.push(nn(this.speed[i]));
      out.current.push(nn(this.current[i]));
    }
    return out;
  }

  last() {
    if (!this.n) return null;
    const i = (this.head - 1 + this.cap) % this.cap;
    return { t: this.t[i], pos: this.pos[i] };
  }
}

export class History {
  constructor(studio) {
    this.studio = studio;
    this.rates = { ...DEFAULT_RATES };
    this.rings = new Map(); // device key -> Ring
    this.targets = new Map(); // device key -> [{t, v}] ascending (deg)
    this.waves = new Map(); // device key -> [{t0, t1, at(t) -> deg}]
    /** Per device key: {silent: bool, error, since} of its last sample. */
    this.health = new Map();
    /** Per bus stream: {family, bus, lastMs, error} (a whole sample that failed, or none for a while). */
    this.buses = new Map();
    this.listeners = new Set();
    this.unsubs = [];
    /** The robot file's joints: {key, name, family, bus, id}; their rings exist from the start. */
    this.robot = (studio.info?.robot ?? []).map((j) => ({ ...j, key: deviceKey("robot", "robot", j.name) }));
    for (const j of this.robot) this.rings.set(j.key, new Ring(KEEP_S * MAX_RATE));
    this.robotUntil = 0;
    this.robotUnsub = null;
    this.#watchRuns();
    studio.on("devices", () => this.restart());
    studio.on("target", (m) => {
      const v = m.family === "wck" ? Number(m.value) * WCK_DEG_PER_STEP : Number(m.value);
      this.addTarget(m.family, m.bus, Number(m.device), m.unix_ms ?? Date.now(), v);
    });
    this.restart();
  }

  /** Listen to every change (a sample or a target); returns the function that stops it. */
  onChange(fn) {
    this.listeners.add(fn);
    return () => this.listeners.delete(fn);
  }

  #changed(what) {
    for (const fn of [...this.listeners]) {
      try {
        fn(what);
      } catch (e) {
        console.warn("history listener", e);
      }
    }
  }

  /** Set the sampling rate (Hz) of a family's buses (restarts their streams). */
  setRate(family, hz) {
    if (this.rates[family] === hz) return;
    this.rates[family] = hz;
    this.restart();
  }

  /** The devices recorded: [{family, bus, id, name, key}]. */
  devices() {
    return ["whj", "wck"].flatMap((family) =>
      this.studio.ids(family).map((d) => ({ family, bus: d.bus, id: d.id, name: d.name, key: deviceKey(family, d.bus, d.id) })),
    );
  }

  /** (Re)subscribe: one stream per bus, every known device of it. */
  restart() {
    for (const u of this.unsubs) u();
    this.unsubs = [];
    const groups = new Map();
    for (const d of this.devices()) {
      const g = `${d.family}|${d.bus}`;
      if (!groups.has(g)) groups.set(g, []);
      groups.get(g).push(d);
      if (!this.rings.has(d.key)) this.rings.set(d.key, new Ring(KEEP_S * MAX_RATE));
    }
    for (const key of [...this.rings.keys()]) {
      if (key.startsWith("robot|")) continue;
      if (!this.devices().some((d) => d.key === key)) {
        this.rings.delete(key);
        this.health.delete(key);
      }
    }
    this.buses.clear();
    for (const [g, ds] of groups) {
      const [family, bus] = g.split("|");
      const ids = ds.map((d) => d.id).join(",");
      const request = family === "whj" ? { op: "whj.sample", bus, joints: ids } : { op: "wck.sample", bus, ids };
      const rate = this.rates[family];
      this.buses.set(g, { family, bus, lastMs: null, error: null, rate });
      this.unsubs.push(
        // Delivered up to twice as often as sampled, so that few samples are skipped.
        this.studio.subscribe(`history.${g}`, request, rate, Math.min(120, rate * 2), (s) => this.#onSample(family, bus, s)),
      );
    }
    this.#changed({ restart: true });
  }

  #onSample(family, bus, s) {
    const b = this.buses.get(`${family}|${bus}`);
    if (b) {
      b.lastMs = Date.now();
      b.error = s.report ? null : s.error ?? s.failed ?? "the reading failed";
      b.late = !!s.late;
    }
    const t = s.unix_ms ?? Date.now();
    for (const r of s.report?.results ?? []) {
      const key = deviceKey(family, bus, r.id);
      const ring = this.rings.get(key);
      if (!ring) continue;
      const was = this.health.get(key);
      if (r.kind) {
        ring.push(t, null, null, null);
        this.health.set(key, { silent: true, kind: r.kind, error: r.error ?? r.kind, since: was?.silent ? was.since : t });
        continue;
      }
      this.health.set(key, { silent: false });
      if (family === "whj") ring.push(t, r.position_deg, r.speed_rpm, r.current_ma);
      else ring.push(t, r.position_deg, r.speed_deg_s == null ? null : r.speed_deg_s / 6, null);
    }
    if (!s.report) {
      // The whole reading failed: every device of the bus is without a reading.
      for (const d of this.devices()) {
        if (d.family !== family || d.bus !== bus) continue;
        this.rings.get(d.key)?.push(t, null, null, null);
      }
    }
    this.#changed({ family, bus });
  }

  /**
   * Every `robot.play` any panel of this page runs (through `studio.runLong`): its joints
   * recorded while it runs and its trajectory drawn as their targets.
   */
  #watchRuns() {
    const studio = this.studio;
    const runLong = studio.runLong.bind(studio);
    studio.runLong = (request, onProgress) => {
      const watch =
        request?.op === "robot.play" ? this.#watchPlay(request) : request?.op === "wck.play" ? this.#watchScene(request) : null;
      const handle = runLong(request, watch ? (p) => (watch(p), onProgress?.(p)) : onProgress);
      if (watch) {
        const end = () => watch(null);
        handle.promise.then(end, end);
      }
      return handle;
    };
  }

  /** The progress handler of a robot.play: its trajectory as targets, its joints recorded. */
  #watchPlay(request) {
    const traj = parseTrajectory(request.trajectory);
    if (!traj) return null;
    const rate = Number(request.rate_hz ?? 50);
    const duration = traj.rows[traj.rows.length - 1][0];
    this.#recordRobot(true);
    let start = null; // ms: the run's first tick
    const segs = [];
    return (p) => {
      if (!p) {
        for (const seg of segs) if (seg.t1 > Date.now()) seg.t1 = Date.now();
        this.#recordRobot(false);
        this.#changed({ target: true });
        return;
      }
      if (p.done == null || !p.total) return;
      // Tick k (done k + 1) went k periods after the first: the earliest estimate is the closest.
      const s0 = Date.now() - ((p.done - 1) / rate) * 1000;
      if (start !== null && s0 >= start) return;
      start = s0;
      // The trajectory's first point is due at its last tick less its duration (after the lead-in).
      const t0 = start + ((p.total - 1) / rate - duration) * 1000;
      if (!segs.length) {
        traj.names.forEach((name, c) => {
          const key = deviceKey("robot", "robot", name);
          if (!this.rings.has(key)) return;
          const seg = { t0, t1: t0 + duration * 1000, at: (t) => interpolate(traj.rows, c + 1, (t - seg.t0) / 1000) };
          if (!this.waves.has(key)) this.waves.set(key, []);
          const list = this.waves.get(key);
          list.push(seg);
          while (list.length > MAX_TARGETS) list.shift();
          segs.push(seg);
        });
      } else {
        for (const seg of segs) {
          seg.t1 -= seg.t0 - t0;
          seg.t0 = t0;
        }
      }
      this.#changed({ target: true });
    };
  }

  /**
   * The progress handler of a wCK keyframe scene (wck.play): its poses as the servos'
   * targets (servos 0..N-1 of the bus, in degrees as wck.status gives them), from its start.
   */
  #watchScene(request) {
    const scene = parseKeyframes(request.motion);
    const bus = request.bus ?? this.studio.buses("wck")[0];
    if (!scene || bus == null) return null;
    const duration = scene.rows[scene.rows.length - 1][0];
    let start = null;
    const segs = [];
    return (p) => {
      if (!p) {
        for (const seg of segs) if (seg.t1 > Date.now()) seg.t1 = Date.now();
        this.#changed({ target: true });
        return;
      }
      if (p.done == null) return;
      // Its progress is the time into the scene (ms): the earliest estimate of its start is the closest.
      const s0 = Date.now() - p.done;
      if (start !== null && s0 >= start) return;
      start = s0;
      if (!segs.length) {
        for (let i = 0; i < scene.servos; i++) {
          const key = deviceKey("wck", bus, i);
          if (!this.rings.has(key)) continue;
          const seg = { t0: start, t1: start + duration * 1000, at: (t) => interpolate(scene.rows, i + 1, (t - seg.t0) / 1000) * WCK_DEG_PER_STEP };
          if (!this.waves.has(key)) this.waves.set(key, []);
          this.waves.get(key).push(seg);
          segs.push(seg);
        }
      } else {
        for (const seg of segs) {
          seg.t1 -= seg.t0 - start;
          seg.t0 = start;
        }
      }
      this.#changed({ target: true });
    };
  }

  /** Record the robot's joints (robot.sample at 20 Hz) while plays run, and 1 s after the last. */
  #recordRobot(on) {
    if (on) {
      this.robotRuns = (this.robotRuns ?? 0) + 1;
      if (!this.robotUnsub) {
        this.robotUnsub = this.studio.subscribe("history.robot", { op: "robot.sample" }, 20, 40, (s) => this.#onRobotSample(s));
      }
      return;
    }
    this.robotRuns = Math.max(0, (this.robotRuns ?? 1) - 1);
    setTimeout(() => {
      if (this.robotRuns === 0 && this.robotUnsub) {
        this.robotUnsub();
        this.robotUnsub = null;
      }
    }, 1000);
  }

  #onRobotSample(s) {
    const t = s.unix_ms ?? Date.now();
    for (const r of s.report?.results ?? []) {
      const ring = this.rings.get(deviceKey("robot", "robot", r.id));
      if (!ring) continue;
      if (r.kind) ring.push(t, null, null, null);
      else ring.push(t, r.position_deg, r.speed_deg_s == null ? null : r.speed_deg_s / 6, r.current_ma);
    }
    this.#changed({ robot: true });
  }

  /** A commanded position target (deg) of a device at `t` (ms). A request without a bus commands the family's only bus. */
  addTarget(family, bus, id, t, v) {
    const key = this.#resolve(family, bus, id);
    if (!key) return;
    if (!this.targets.has(key)) this.targets.set(key, []);
    const list = this.targets.get(key);
    let i = list.length;
    while (i > 0 && list[i - 1].t > t) i--;
    list.splice(i, 0, { t, v });
    this.#trimTargets(list);
    this.#changed({ target: key });
  }

  /** The signal a wave asks of a device from `t0` to `t1` (ms): `at(t)` its value (deg) at `t`. */
  addWave(family, bus, id, t0, t1, at) {
    const key = this.#resolve(family, bus, id);
    if (!key) return null;
    if (!this.waves.has(key)) this.waves.set(key, []);
    const seg = { t0, t1, at };
    const list = this.waves.get(key);
    list.push(seg);
    while (list.length > MAX_TARGETS) list.shift();
    this.#changed({ target: key });
    return seg;
  }

  /** End a wave's segment early (it was stopped) at `t` (ms). */
  endWave(seg, t) {
    if (seg && t < seg.t1) {
      seg.t1 = t;
      this.#changed({ target: true });
    }
  }

  #resolve(family, bus, id) {
    const d = this.devices().find((x) => x.family === family && x.id === id && (bus == null || x.bus === bus));
    return d?.key ?? null;
  }

  #trimTargets(list) {
    const tmin = Date.now() - KEEP_S * 1000;
    let k = 0; // keep the one in force at the start
    while (k + 1 < list.length && list[k + 1].t < tmin) k++;
    if (k) list.splice(0, k);
    while (list.length > MAX_TARGETS) list.shift();
  }

  /** A device's readings since `tmin` (ms), oldest first. */
  readings(key, tmin) {
    return this.rings.get(key)?.since(tmin) ?? { t: [], pos: [], speed: [], current: [] };
  }

  /** A device's last reading, {t, pos} or null. */
  last(key) {
    return this.rings.get(key)?.last() ?? null;
  }

  /**
   * The target in force at each of the times `ts` (ms): a wave's asked signal within its
   * segment, else the last commanded step before it, else null.
   */
  targetAt(key, ts) {
    const list = this.targets.get(key) ?? [];
    const waves = this.waves.get(key) ?? [];
    const out = new Array(ts.length).fill(null);
    let j = -1;
    for (let i = 0; i < ts.length; i++) {
      const t = ts[i];
      while (j + 1 < list.length && list[j + 1].t <= t) j++;
      let v = j >= 0 ? list[j].v : null;
      let since = j >= 0 ? list[j].t : -Infinity;
      for (const w of waves) {
        if (t >= w.t0 && t <= w.t1 && w.t0 >= since) {
          v = w.at(t);
          since = w.t0;
        }
      }
      out[i] = v;
    }
    return out;
  }

  /** The times (ms) at which a device's targets step or its wave segments begin and end, within [tmin, tmax]. */
  targetTimes(key, tmin, tmax) {
    const out = [];
    for (const p of this.targets.get(key) ?? []) if (p.t >= tmin && p.t <= tmax) out.push(p.t);
    for (const w of this.waves.get(key) ?? []) {
      if (w.t1 < tmin || w.t0 > tmax) continue;
      // A wave's signal drawn at 50 points a second between the readings.
      for (let t = Math.max(w.t0, tmin); t <= Math.min(w.t1, tmax); t += 20) out.push(t);
      if (w.t1 <= tmax) out.push(w.t1);
    }
    return out;
  }

  /** The silent devices now: [{family, bus, id, name, key, error, since}], and the buses without readings. */
  silent() {
    const devices = [];
    for (const d of this.devices()) {
      const h = this.health.get(d.key);
      if (h?.silent) devices.push({ ...d, error: h.error, since: h.since });
    }
    const buses = [];
    const now = Date.now();
    for (const b of this.buses.values()) {
      if (b.error) buses.push({ ...b, why: b.error });
      else if (b.lastMs != null && now - b.lastMs > Math.max(2000, 4000 / b.rate)) {
        buses.push({ ...b, why: `no reading for ${((now - b.lastMs) / 1000).toFixed(1)} s` });
      }
    }
    return { devices, buses };
  }
}

/**
 * A keyframe scene's text (`torque`, `pose MS P0 P1 …`, `hold MS`: the motion file of
 * `robobus wck play`) as points in time: the first pose at once, held for its time, each
 * later one reached linearly in its time, a hold keeping the pose. {servos, rows: [[s, steps…]]}, or null.
 */
function parseKeyframes(text) {
  if (typeof text !== "string") return null;
  const rows = [];
  let t = 0;
  let last = null;
  for (const line of text.split(/\r?\n/).slice(0, 100_000)) {
    const w = line.split("#")[0].trim().split(/\s+/).filter(Boolean);
    if (w[0] === "pose" && w.length > 2) {
      const ms = Number(w[1]);
      const pos = w.slice(2).map(Number);
      if (!Number.isFinite(ms) || pos.some((v) => !Number.isFinite(v))) return null;
      if (last === null) rows.push([0, ...pos], [ms / 1000, ...pos]);
      else rows.push([(t + ms) / 1000, ...pos]);
      t += ms;
      last = pos;
    } else if (w[0] === "hold" && last) {
      t += Number(w[1]) || 0;
      rows.push([t / 1000, ...last]);
    }
  }
  return last ? { servos: last.length, rows } : null;
}

/** A trajectory file's text (`time_s`, then a column per joint): {names, rows: [[t, v...]]}, or null. */
function parseTrajectory(text) {
  if (typeof text !== "string") return null;
  const lines = text.split(/\r?\n/).map((l) => l.trim()).filter((l) => l && !l.startsWith("#"));
  if (lines.length < 2) return null;
  const head = lines[0].split(",").map((c) => c.trim());
  if (head[0] !== "time_s") return null;
  const rows = lines.slice(1, 100_001).map((l) => l.split(",").map(Number));
  if (rows.some((r) => r.length !== head.length || r.some((v) => !Number.isFinite(v)))) return null;
  return { names: head.slice(1), rows };
}

/** Column `c` of the trajectory's rows at `t` seconds, linearly between its points. */
function interpolate(rows, c, t) {
  if (t <= rows[0][0]) return rows[0][c];
  for (let i = 1; i < rows.length; i++) {
    if (t <= rows[i][0]) {
      const [a, b] = [rows[i - 1], rows[i]];
      const f = b[0] === a[0] ? 1 : (t - a[0]) / (b[0] - a[0]);
      return a[c] + f * (b[c] - a[c]);
    }
  }
  return rows[rows.length - 1][c];
}
