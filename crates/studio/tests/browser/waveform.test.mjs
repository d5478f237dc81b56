// The Waveform panel: a sine on WHJ joint 1 of the simulated robot moves the simulated
// joint, its statistics table shows the report's summary; Stop ends a wave early; the
// panel refuses to start while disarmed.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startStudio, launchBrowser, openPage, simJoint, screenshot, openTab, arm, teardown, until } from "./harness.mjs";

let studio;
let browser;
let page;
let errors;
let panel;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  panel = await openTab(page, "Waveform");
});

after(() => teardown(browser, studio));

test("disarmed, the wave cannot start", async () => {
  await page.waitForFunction(() => window.studio.state.controller === true);
  assert.equal(await panel.getByRole("button", { name: "Start wave" }).isDisabled(), true);
  await panel.getByText("Take control and arm to run a wave.").waitFor();
});

test("a sine on joint 1 moves the simulated joint and shows its tracking statistics", async () => {
  await arm(page);
  const start = panel.getByRole("button", { name: "Start wave" });
  await until(async () => !(await start.isDisabled()), { what: "Start wave enabled after arming" });
  await panel.getByLabel("Joint", { exact: true }).selectOption({ label: "Joint 1 · j1" });
  await panel.getByLabel("Amplitude (deg)").fill("20");
  // Gentle enough that the joint never lags 10 deg behind (the joint refuses a target
  // further than that from where it is: error "position command step").
  await panel.getByLabel("Offset (deg)").fill("5");
  await panel.getByLabel("Frequency (Hz)").fill("0.5");
  await panel.getByLabel("Duration (s)").fill("2");
  await panel.getByLabel("Rate (frames/s)").fill("100");
  await start.click();
  // It starts 5 deg from the joint: its lead-in set-points are clamped, which the panel
  // says before anything is sent; it runs when confirmed.
  const warning = panel.getByRole("alert").filter({ hasText: "set-points would be clamped" });
  await warning.waitFor();
  assert.equal(await page.evaluate(() => window.studio.pending.size), 0, "nothing started before the confirmation");
  await warning.getByRole("button", { name: "Run anyway" }).click();
  // While it runs, the simulated joint swings around the offset.
  let lo = Infinity;
  let hi = -Infinity;
  const status = panel.getByRole("status");
  await until(async () => {
    const j = await simJoint(studio.url, 1);
    lo = Math.min(lo, j.position_deg);
    hi = Math.max(hi, j.position_deg);
    return /Wave done|failed/.test(await status.textContent());
  }, { timeout: 10_000, interval: 50, what: "the wave to end" }).catch(async (e) => {
    throw new Error(`${e.message}; the panel says: ${await status.textContent()}; ${await panel.locator(".progress").textContent()}`);
  });
  assert.match(await status.textContent(), /Wave done: 200 frames/);
  assert.ok(hi > 20 && lo < -10, `the joint swung ${lo}..${hi} deg`);
  // A sine of whole periods ends near the offset (the step limiter lags the jump to
  // the offset at the start by a few degrees), where the joint holds.
  const j = await simJoint(studio.url, 1);
  assert.ok(Math.abs(j.position_deg - 5) < 5, `joint 1 ends near the 5 deg offset: ${j.position_deg}`);
  assert.equal(j.enabled, true);

  const table = panel.getByRole("table", { name: /Tracking statistics, joint 1/ });
  const row = (name) => table.getByRole("row", { name: new RegExp(`^${name}`) });
  assert.match(await row("Frames sent").textContent(), /Frames sent200/);
  assert.match(await row("Frames answered").textContent(), /200/);
  assert.match(await row("Tracking error, RMS").textContent(), /\d\.\d+deg/);
  assert.match(await row("Round trip, median").textContent(), /\d+µs/);
  await screenshot(page, "waveform");
});

test("a sine started from where the joint rests runs without the clamp question", async () => {
  // From rest its first set-points are held back by hundredths of a degree while the
  // speed builds up (the acceleration limit): less than the 0.1 deg the panel asks about.
  const at = (await simJoint(studio.url, 1)).position_deg;
  await panel.getByLabel("Amplitude (deg)").fill("10");
  await panel.getByLabel("Offset (deg)").fill(at.toFixed(3));
  await panel.getByLabel("Frequency (Hz)").fill("0.5");
  await panel.getByLabel("Duration (s)").fill("2");
  await panel.getByLabel("Rate (frames/s)").fill("100");
  await panel.getByRole("button", { name: "Start wave" }).click();
  const status = panel.getByRole("status");
  await until(async () => /Wave done|failed|Not started/.test(await status.textContent()), {
    timeout: 10_000, interval: 50, what: "the wave to end",
  });
  assert.match(await status.textContent(), /Wave done: 200 frames/);
  assert.equal(await panel.getByRole("alert").filter({ hasText: "set-points would be clamped" }).isVisible(), false);
});

test("a speed wave sets the joint's mode first; Stop ends it early", async () => {
  await panel.getByLabel("Mode", { exact: true }).selectOption("speed");
  await panel.getByLabel("Amplitude (RPM)").fill("5");
  await panel.getByLabel("Offset (RPM)").fill("0");
  await panel.getByLabel("Duration (s)").fill("20");
  await panel.getByRole("button", { name: "Start wave" }).click();
  const status = panel.getByRole("status");
  await panel.getByText("Wave running on joint 1").waitFor();
  await until(async () => (await simJoint(studio.url, 1)).mode !== 3, { what: "the joint out of position mode" });
  await page.waitForTimeout(300);
  await panel.getByRole("button", { name: "Stop wave" }).click();
  await until(async () => /Stopped/.test(await status.textContent()), { timeout: 5000, what: "the stop" });
  const j = await simJoint(studio.url, 1);
  assert.equal(j.enabled, true, "on_stop hold keeps the joint enabled");
  assert.ok(Math.abs(j.target_speed_rpm ?? 0) < 0.01, `a stopped speed wave holds at speed 0: ${JSON.stringify(j)}`);
  assert.equal(await panel.getByRole("button", { name: "Stop wave" }).isDisabled(), true);
  assert.equal(await panel.getByRole("button", { name: "Start wave" }).isDisabled(), false);
});

test("Show dry run opens the Preview panel with the wave", async () => {
  await panel.getByRole("button", { name: "Show dry run" }).click();
  const preview = page.getByRole("tabpanel", { name: "Preview" });
  await preview.waitFor();
  const json = JSON.parse(await preview.getByLabel("Request (JSON)").inputValue());
  assert.equal(json.op, "whj.wave");
  assert.equal(json.mode, "speed");
  await preview.getByText(/Dry run of whj\.wave/).waitFor();
  assert.match(await preview.getByLabel("Dry run: bytes and frames").textContent(), /^301##1/m);
  assert.deepEqual(errors, []);
});

test("a read-only studio offers no wave, upload or scene play", async () => {
  const ro = await startStudio(["--read-only"]);
  try {
    const { page: p, errors: errs } = await openPage(browser, ro.url);
    const wave = await openTab(p, "Waveform");
    await wave.getByText("Read-only studio: waves are not served.").waitFor();
    assert.equal(await wave.getByRole("button", { name: "Start wave" }).isDisabled(), true);
    const program = await openTab(p, "Program");
    await program.getByText("Read-only studio: uploads are not served.").waitFor();
    assert.equal(await program.getByRole("button", { name: "Upload", exact: true }).isDisabled(), true);
    assert.equal(await program.getByRole("button", { name: "Check", exact: true }).isDisabled(), false);
    const poses = await openTab(p, "Poses");
    await poses.getByText("Read-only studio: recording only.").waitFor();
    assert.equal(await poses.getByRole("button", { name: "Play scene" }).isDisabled(), true);
    assert.equal(await poses.getByRole("button", { name: "Make passive" }).isDisabled(), true);
    assert.equal(await poses.getByRole("button", { name: "Record pose" }).isDisabled(), false);
    await poses.getByText("Read-only studio: robot poses are recorded, not gone to.").waitFor();
    assert.equal(await poses.getByRole("button", { name: "Play poses" }).isDisabled(), true);
    assert.equal(await poses.getByRole("button", { name: "Record robot pose" }).isDisabled(), false);
    assert.deepEqual(errs, []);
  } finally {
    await ro.stop();
  }
});
