// The shell: the header (connection, control, arming, the silent devices of the page's
// history, why the page was disarmed; it stays at the top of the window), the stop key
// (Escape), the safe-state banner and the tabs. The page's history (history.js) records
// every device from the moment the page connects. Each panel is a module ./panels/NAME.js whose default export is
// {id, title, mount(element, studio)}; it is loaded and mounted the first time its tab shows.
// A mounted panel's element gets the DOM events `studio:show` and `studio:hide`.

import { Studio, el, describeError } from "./core.js";
import { History } from "./history.js";

const PANELS = [
  ["bus", "Bus"],
  ["device", "Device"],
  ["settings", "Settings"],
  ["backup", "Backup"],
  ["commission", "Commission"],
  ["tune", "Tune"],
  ["plot", "Plot"],
  ["waveform", "Waveform"],
  ["program", "Program"],
  ["poses", "Poses"],
  ["robotops", "Robot"],
  ["preview", "Preview"],
  ["capture", "Capture"],
];

const app = document.getElementById("app");

async function main() {
  let studio;
  try {
    studio = await Studio.connect();
  } catch (e) {
    app.replaceChildren(
      el("div", { className: "fatal", role: "alert" }, [
        el("h1", {}, "robobus studio"),
        el("p", {}, `Could not connect to the studio server: ${describeError(e)}`),
        el("button", { type: "button", onclick: () => location.reload() }, "Retry"),
      ]),
    );
    return;
  }
  window.studio = studio; // for the console and the browser tests
  // Every device's readings from now on, whichever panel shows them.
  studio.history = new History(studio);
  app.replaceChildren(header(studio), safeBanner(studio), tabs(studio));
  stopKey(studio);
}

/**
 * Escape stops everything: every run of this page and the arming (the server brings what
 * moved to its safe state). It works everywhere, in a field or a dialog too: Escape types
 * nothing, so it cannot be pressed by accident while typing, and the stop key must always
 * work. Listened to first (capture), so no panel can swallow it.
 */
function stopKey(studio) {
  addEventListener(
    "keydown",
    (e) => {
      if (e.key !== "Escape" || e.repeat) return;
      const armed = studio.state.armed;
      const runs = studio.stopAll();
      if (armed || runs) {
        const what = [armed ? "disarmed" : null, runs ? `${runs} run${runs === 1 ? "" : "s"} stopped` : null];
        studio.toast(`Escape: ${what.filter(Boolean).join(", ")}.`, "ok");
      }
    },
    { capture: true },
  );
}

function header(studio) {
  const conn = el("span", { className: "pill", id: "conn-state" });
  const control = el("span", { className: "pill", id: "control-state" });
  const armed = el("span", { className: "pill", id: "arm-state" });
  const arm = el("button", { type: "button", className: "arm", onclick: () => studio.arm() }, "Arm");
  const disarm = el(
    "button",
    { type: "button", className: "danger", ariaLabel: "Disarm", "aria-keyshortcuts": "Escape", title: "Disarm and stop everything (Escape)", onclick: () => studio.disarm() },
    ["Disarm ", el("kbd", {}, "Esc")],
  );
  const take = el("button", { type: "button", className: "secondary", onclick: () => studio.takeControl() }, "Take control");
  const release = el(
    "button",
    { type: "button", className: "secondary", onclick: () => studio.releaseControl() },
    "Release control",
  );
  const reasonText = el("span", {});
  const reason = el("div", { className: "disarm-reason", id: "disarm-reason", role: "alert", hidden: true }, [
    reasonText,
    el("button", { type: "button", className: "link", ariaLabel: "Dismiss why the page was disarmed", onclick: () => (reason.hidden = true) }, "×"),
  ]);
  studio.on("disarmed", (d) => {
    if (!d) {
      reason.hidden = true;
      return;
    }
    const at = new Date(d.unixMs).toLocaleTimeString();
    reasonText.replaceChildren(el("strong", {}, `Disarmed at ${at}: ${d.reason}.`), ` ${capital(d.why)}. Arm again when ready.`);
    reason.hidden = false;
  });
  const where = studio.state.simulated ? "simulated robot" : "hardware";
  const buses = [...studio.buses("wck"), ...studio.buses("whj")].join(", ");

  function update() {
    const s = studio.state;
    conn.textContent = s.connected ? "connected" : "reconnecting…";
    conn.className = `pill ${s.connected ? "ok" : "warn"}`;
    if (s.readOnly) control.textContent = "read-only";
    else if (s.controller) control.textContent = "you control the devices";
    else if (s.heldByOther) control.textContent = "another page controls: watching";
    else control.textContent = "watching (nobody controls)";
    control.className = `pill ${s.controller ? "ok" : ""}`;
    armed.textContent = s.armed ? "ARMED: motion allowed" : "disarmed";
    armed.className = `pill ${s.armed ? "armed" : ""}`;
    armed.hidden = s.readOnly;
    arm.hidden = s.readOnly || !s.controller || s.armed;
    disarm.hidden = s.readOnly || !s.armed;
    take.hidden = s.readOnly || s.controller;
    take.disabled = !s.connected;
    release.hidden = s.readOnly || !s.controller;
    document.body.classList.toggle("armed", s.armed);
  }
  studio.on("state", update);
  let heldBefore = false;
  studio.on("control", (m) => {
    if (!m.controller && m.held_by_other && !heldBefore && !studio.state.readOnly) {
      studio.toast("Another page controls the devices: this page watches.");
    }
    heldBefore = !m.controller && m.held_by_other;
  });
  update();
  return el("header", { className: "top" }, [
    el("h1", {}, ["robobus studio", el("small", {}, ` ${where}${buses ? ` · ${buses}` : ""} · v${studio.info.version}`)]),
    el("div", { className: "status", "aria-label": "Studio state" }, [conn, control, armed, silentFlag(studio)]),
    el("div", { className: "controls" }, [take, release, arm, disarm]),
    reason,
  ]);
}

/**
 * The silent devices, on every tab: a device of the page's history whose last reading
 * failed, or a bus whose reading failed or stopped coming. Clicking it opens the first
 * silent device in the Device panel.
 */
function silentFlag(studio) {
  const flag = el("button", { type: "button", className: "pill bad silent-flag", id: "silent-state", hidden: true });
  flag.setAttribute("aria-live", "polite");
  let first = null;
  flag.addEventListener("click", async () => {
    if (!first || !studio.showPanel) return;
    const panel = await studio.showPanel("device");
    const sel = panel.querySelector("select.device-select");
    const value = `${first.family}|${first.bus}|${first.id}`;
    if (sel && [...sel.options].some((o) => o.value === value)) {
      sel.value = value;
      sel.dispatchEvent(new Event("change"));
    }
  });
  let queued = false;
  const render = () => {
    queued = false;
    const { devices, buses } = studio.history.silent();
    const names = devices.map((d) => `${d.family === "wck" ? "servo" : "joint"} ${d.id}${d.name ? ` · ${d.name}` : ""}`);
    const busText = buses.map((b) => `${b.bus}: ${b.why}`);
    first = devices[0] ?? null;
    const parts = [];
    if (names.length) parts.push(`silent: ${names.slice(0, 4).join(", ")}${names.length > 4 ? ` and ${names.length - 4} more` : ""}`);
    if (busText.length) parts.push(busText.join("; "));
    const text = parts.join(" · ");
    if (flag.textContent !== text) flag.textContent = text;
    flag.hidden = !text;
    flag.title = devices.length
      ? `${devices.map((d) => `${d.family === "wck" ? "Servo" : "Joint"} ${d.id} (${d.bus}): ${d.error}`).join("\n")}\nClick to open ${names[0]} in Device.`
      : busText.join("\n");
  };
  studio.history.onChange(() => {
    if (!queued) {
      queued = true;
      setTimeout(render, 200);
    }
  });
  setInterval(render, 1000); // a bus whose readings stopped coming
  render();
  return flag;
}

function capital(text) {
  return text ? text[0].toUpperCase() + text.slice(1) : "";
}

function safeBanner(studio) {
  const banner = el("div", { className: "safe-banner", role: "alert", hidden: true });
  studio.on("safe", (m) => {
    const devices = (m.devices ?? []).map(deviceName).join(", ");
    const failures = (m.failures ?? []).map((f) => (typeof f === "string" ? f : f.error ?? JSON.stringify(f)));
    const dismiss = el("button", { type: "button", className: "secondary", onclick: () => (banner.hidden = true) }, "Dismiss");
    banner.replaceChildren(
      el("div", {}, [
        el("strong", {}, "Devices brought to the safe state"),
        el("span", {}, `, reason: ${m.reason}.`),
        devices ? el("div", {}, `${devices}${m.state ? `: ${m.state}` : ""}.`) : null,
        failures.length ? el("div", { className: "fail" }, `Failures: ${failures.join("; ")}`) : null,
      ]),
      dismiss,
    );
    banner.hidden = false;
  });
  return banner;
}

function deviceName(d) {
  if (typeof d === "string" || typeof d === "number") return String(d);
  const fam = d.family === "wck" ? "Servo" : d.family === "whj" ? "Joint" : "Device";
  const id = d.device ?? d.id;
  return `${fam} ${id}${d.bus ? ` (${d.bus})` : ""}`;
}

function tabs(studio) {
  const list = el("div", { className: "tabs", role: "tablist", ariaLabel: "Panels" });
  const main = el("main", {});
  const panels = new Map(); // id -> {tab, panel, mounted: Promise|null}
  let current = null;

  for (const [id, title] of PANELS) {
    const tab = el("button", {
      type: "button",
      role: "tab",
      id: `tab-${id}`,
      "aria-controls": `panel-${id}`,
      "aria-selected": "false",
      tabIndex: -1,
    }, title);
    const panel = el("section", { role: "tabpanel", id: `panel-${id}`, "aria-labelledby": `tab-${id}`, hidden: true });
    tab.addEventListener("click", () => show(id));
    tab.addEventListener("keydown", (e) => {
      const ids = PANELS.map((p) => p[0]);
      let i = ids.indexOf(id);
      if (e.key === "ArrowRight") i = (i + 1) % ids.length;
      else if (e.key === "ArrowLeft") i = (i - 1 + ids.length) % ids.length;
      else if (e.key === "Home") i = 0;
      else if (e.key === "End") i = ids.length - 1;
      else return;
      e.preventDefault();
      show(ids[i]).then(() => panels.get(ids[i]).tab.focus());
    });
    list.append(tab);
    main.append(panel);
    panels.set(id, { tab, panel, title, mounted: null });
  }

  async function mount(id) {
    const p = panels.get(id);
    if (!p.mounted) {
      p.mounted = (async () => {
        try {
          const mod = await import(`./panels/${id}.js`);
          await mod.default.mount(p.panel, studio);
        } catch (e) {
          console.error(`panel ${id}`, e);
          p.panel.replaceChildren(
            el("p", { className: "fail" }, `The ${p.title} panel could not be loaded: ${describeError(e)}`),
          );
        }
      })();
    }
    return p.mounted;
  }

  async function show(id) {
    if (current === id) return panels.get(id).panel;
    if (current) {
      const old = panels.get(current);
      old.tab.setAttribute("aria-selected", "false");
      old.tab.tabIndex = -1;
      old.panel.hidden = true;
      old.panel.dispatchEvent(new CustomEvent("studio:hide"));
    }
    current = id;
    const p = panels.get(id);
    p.tab.setAttribute("aria-selected", "true");
    p.tab.tabIndex = 0;
    p.panel.hidden = false;
    try {
      sessionStorage.setItem("robobus-studio-tab", id);
    } catch {
      /* storage may be off */
    }
    await mount(id);
    if (current === id) p.panel.dispatchEvent(new CustomEvent("studio:show"));
    return p.panel;
  }

  studio.showPanel = show;
  let first = "bus";
  try {
    const saved = sessionStorage.getItem("robobus-studio-tab");
    if (saved && panels.has(saved)) first = saved;
  } catch {
    /* storage may be off */
  }
  show(first);
  return el("div", { className: "body" }, [list, main]);
}

main();
