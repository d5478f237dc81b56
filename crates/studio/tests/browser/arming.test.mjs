// Arming as a person uses it: the page stays armed on a machine whose cores are all busy
// while it clicks through every panel (its heartbeat does not wait for the page's main
// thread), a page that really hangs loses control and says why, the header with Disarm
// stays on screen, and Escape stops everything, from a field too.

import { test, after } from "node:test";
import assert from "node:assert/strict";
import { spawn } from "node:child_process";
import { availableParallelism } from "node:os";
import { startStudio, launchBrowser, openPage, screenshot, openTab, arm, until } from "./harness.mjs";

const PANELS = ["Bus", "Device", "Tune", "Plot", "Waveform", "Program", "Poses", "Preview", "Capture"];

let browser;
const servers = [];

after(async () => {
  await browser?.close().catch(() => {});
  for (const s of servers) await s.stop();
});

async function studio(args = []) {
  const s = await startStudio(args);
  servers.push(s);
  browser ??= await launchBrowser();
  return s;
}

/**
 * Keep every core busy: one busy loop per core in its own process, each ending by itself
 * after `seconds` (so nothing outlives a crashed test) and stopped by `stop()`.
 */
function burnCores(seconds) {
  const procs = [];
  for (let i = 0; i < availableParallelism(); i++) {
    procs.push(
      spawn(process.execPath, ["-e", `const end = Date.now() + ${seconds * 1000}; while (Date.now() < end) {}`], {
        stdio: "ignore",
      }),
    );
  }
  return {
    running: () => procs.filter((p) => p.exitCode === null && p.signalCode === null).length,
    stop: () => {
      for (const p of procs) if (p.exitCode === null && p.signalCode === null) p.kill("SIGKILL");
    },
  };
}

/** Record in the page every safe stop and every disarm it did not ask for. */
async function recordDisarms(page) {
  await page.evaluate(() => {
    window.seenSafe = [];
    window.seenDisarmed = [];
    window.studio.on("safe", (m) => window.seenSafe.push(m.reason));
    window.studio.on("disarmed", (d) => d && window.seenDisarmed.push(`${d.reason}: ${d.why}`));
  });
}

/** Block the page's main thread for `ms`, as a long layout or a heavy chart on a busy machine does. */
function freezePage(page, ms) {
  return page.evaluate((ms) => {
    const end = performance.now() + ms;
    while (performance.now() < end) {
      /* busy */
    }
  }, ms);
}

test("with every core busy, the page arms once and stays armed through every panel at the studio's default allowance", async () => {
  // The studio's default allowance: what a user runs.
  const s = await studio();
  const allowance = (await (await fetch(new URL("api/info", s.url))).json()).heartbeat_timeout_ms;
  const burn = burnCores(120);
  try {
    const { page, errors, context } = await openPage(browser, s.url);
    await recordDisarms(page);
    await arm(page);
    for (let round = 0; round < 2; round++) {
      for (const name of PANELS) {
        const panel = await openTab(page, name);
        await panel.locator("*").first().waitFor();
        await page.waitForTimeout(250);
      }
    }
    // A main thread blocked past the server's allowance (and within the page's 2 s) is a
    // busy page, not a dead one: the link's worker keeps beating.
    await freezePage(page, allowance + 300);
    await page.waitForTimeout(500);
    assert.equal(burn.running(), availableParallelism(), "the cores were kept busy throughout");
    assert.deepEqual(await page.evaluate(() => [window.seenSafe, window.seenDisarmed]), [[], []]);
    assert.equal(await page.evaluate(() => window.studio.state.armed), true);
    // The server agrees: a jog, which needs arming, is obeyed.
    const jogged = await page.evaluate(() => window.studio.jog("whj", "sim-whj", 1, 0.5));
    assert.equal(jogged.type, "jogged");
    assert.deepEqual(await page.evaluate(() => window.seenSafe), []);
    assert.deepEqual(errors, []);
    await context.close();
  } finally {
    burn.stop();
  }
});

test("a page frozen past its allowance loses control, and the header says why until the next Arm", async () => {
  const s = await studio();
  const { page, errors, context } = await openPage(browser, s.url);
  await arm(page);
  // Move a joint so that the safe state has a device to hold.
  await page.evaluate(() => window.studio.jog("whj", "sim-whj", 1, 1));
  // Past the page's 2 s and the server's allowance: a hung page.
  await freezePage(page, 4000);
  const reason = page.locator("header").getByRole("alert");
  await reason.waitFor({ timeout: 5000 });
  const text = await reason.textContent();
  assert.match(text, /Disarmed at .*: heartbeat lost\. This page did not respond for over 2\.\d s/);
  assert.match(text, /Arm again when ready/);
  await until(() => page.evaluate(() => window.studio.state.armed === false), { what: "disarmed" });
  await page.getByText("disarmed", { exact: true }).waitFor();
  // The devices were held; the banner under the header says so too.
  await page.getByRole("alert").filter({ hasText: "Devices brought to the safe state" }).waitFor();
  await screenshot(page, "arming-heartbeat-lost");
  // The reason stays (it is not a toast) until the next Arm.
  await page.waitForTimeout(1000);
  assert.equal(await reason.isVisible(), true);
  await arm(page);
  await reason.waitFor({ state: "hidden" });
  assert.deepEqual(errors, []);
  await context.close();
});

test("a dropped connection while armed says so in the header", async () => {
  const s = await studio();
  const { page, errors, context } = await openPage(browser, s.url);
  await arm(page);
  await page.evaluate(() => window.studio.ws.close());
  const reason = page.locator("header").getByRole("alert");
  await reason.waitFor({ timeout: 5000 });
  assert.match(await reason.textContent(), /connection lost\. The connection to the studio server was lost/);
  await page.getByText("you control the devices").waitFor();
  assert.equal(await reason.isVisible(), true, "still shown after the reconnect");
  assert.deepEqual(errors, []);
  await context.close();
});

test("a link worker that dies while armed is a lost connection: the page says so and reconnects, disarmed", async () => {
  const s = await studio();
  const { page, errors, context } = await openPage(browser, s.url);
  await arm(page);
  await page.evaluate(() => {
    window.linkBefore = window.studio.ws;
    window.studio.ws.worker.terminate();
  });
  const reason = page.locator("header").getByRole("alert");
  await reason.waitFor({ timeout: 8000 });
  assert.match(await reason.textContent(), /connection lost/);
  await until(() => page.evaluate(() => window.studio.state.connected && window.studio.ws !== window.linkBefore), {
    what: "a new connection",
    timeout: 8000,
  });
  await page.getByText("you control the devices").waitFor();
  assert.equal(await page.evaluate(() => window.studio.state.armed), false);
  // The dead worker's WebSocket closed: the server's only controller is this page's new one.
  const other = await openPage(browser, s.url);
  await other.page.getByText("another page controls: watching").waitFor();
  await other.context.close();
  assert.deepEqual(errors, []);
  await context.close();
});

test("Disarm stays on screen when the page is scrolled to its end", async () => {
  const s = await studio();
  const { page, errors, context } = await openPage(browser, s.url, { viewport: { width: 1000, height: 480 } });
  await arm(page);
  // The longest panel.
  let longest = null;
  let height = 0;
  for (const name of PANELS) {
    await openTab(page, name);
    await page.waitForTimeout(200);
    const h = await page.evaluate(() => document.documentElement.scrollHeight);
    if (h > height) [longest, height] = [name, h];
  }
  await openTab(page, longest);
  assert.ok(height > 480 * 1.5, `the ${longest} panel is long enough to scroll (${height} px)`);
  await page.evaluate(() => window.scrollTo(0, document.documentElement.scrollHeight));
  await until(() => page.evaluate(() => window.scrollY > 200), { what: "scrolled" });
  const disarm = page.getByRole("button", { name: "Disarm", exact: true });
  const box = await disarm.boundingBox();
  assert.ok(box && box.y >= 0 && box.y + box.height <= 480, `Disarm in the window: ${JSON.stringify(box)}`);
  assert.equal(await disarm.getAttribute("aria-keyshortcuts"), "Escape");
  // What is at Disarm's place is Disarm (nothing covers it).
  const hit = await page.evaluate(({ x, y }) => document.elementFromPoint(x, y)?.closest("button")?.getAttribute("aria-label"), {
    x: box.x + box.width / 2,
    y: box.y + box.height / 2,
  });
  assert.equal(hit, "Disarm");
  await screenshot(page, "arming-scrolled");
  await page.screenshot({ path: `${process.env.STUDIO_SCREENS ?? "target/studio-screens"}/arming-scrolled-window.png` });
  await disarm.click();
  await until(() => page.evaluate(() => window.studio.state.armed === false), { what: "disarmed" });
  assert.deepEqual(errors, []);
  await context.close();
});

test("Escape in a field stops a running wave and disarms; typing in the field does not", async () => {
  const s = await studio();
  const { page, errors, context } = await openPage(browser, s.url);
  await recordDisarms(page);
  await arm(page);
  const panel = await openTab(page, "Waveform");
  const start = panel.getByRole("button", { name: "Start wave" });
  await until(async () => !(await start.isDisabled()), { what: "Start wave enabled after arming" });
  await panel.getByLabel("Joint", { exact: true }).selectOption({ label: "Joint 1 · j1" });
  await panel.getByLabel("Amplitude (deg)").fill("10");
  await panel.getByLabel("Offset (deg)").fill("0");
  await panel.getByLabel("Frequency (Hz)").fill("0.5");
  await panel.getByLabel("Duration (s)").fill("30");
  // A sine from rest starts at once (its catch-up changes set-points by less than the
  // 0.1 deg the panel asks about).
  await start.click();
  await panel.getByText(/Wave running on joint 1/).waitFor();
  // Typing in a field, keys and all, leaves the page armed and the wave running.
  const amplitude = panel.getByLabel("Amplitude (deg)");
  await amplitude.focus();
  await page.keyboard.type("12 d s");
  await page.keyboard.press("Backspace");
  await page.keyboard.press("Space");
  assert.equal(await page.evaluate(() => window.studio.state.armed), true);
  assert.equal(await page.evaluate(() => window.studio.pending.size), 1, "the wave still runs");
  // Escape, with the focus still in the field.
  const pressed = Date.now();
  await page.keyboard.press("Escape");
  await until(() => page.evaluate(() => window.studio.state.armed === false), { what: "disarmed", timeout: 3000 });
  await panel.getByText(/Stopped|ended with a failure/).waitFor({ timeout: 3000 });
  assert.ok(Date.now() - pressed < 3000);
  assert.equal(await page.evaluate(() => window.studio.pending.size), 0, "no run left");
  // The page asked: the safe stop says "disarmed", and no unasked-disarm reason shows.
  await until(() => page.evaluate(() => window.seenSafe.includes("disarmed")), { what: "the safe stop" });
  assert.deepEqual(await page.evaluate(() => window.seenDisarmed), []);
  assert.equal(await page.locator("#disarm-reason").isVisible(), false);
  await page.getByText("Escape: disarmed, 1 run stopped.").waitFor();
  assert.deepEqual(errors, []);
  await context.close();
});
