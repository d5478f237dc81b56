// Charts where the action is: every device recorded from the moment the page opens (the
// Plot's ticking chooses what is drawn), in a bounded ring per device; a wave's asked
// signal drawn as its target in the Plot; live mini-charts in Device and Waveform that
// show what the same request through the API reads; and a wave whose set-points would be
// clamped does not start until "Run anyway".

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { readFile } from "node:fs/promises";
import { startStudio, launchBrowser, openPage, runRequest, simJoint, screenshot, openTab, arm, teardown, until } from "./harness.mjs";
import { docShot } from "./cli.mjs";

let studio;
let browser;
let page;
let errors;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  await page.waitForFunction(() => window.studio.state.controller === true);
});

after(() => teardown(browser, studio));

/** The non-null values of series `i` of the uPlot chart in the figure named `name`. */
const chartValues = (name, i) =>
  page.evaluate(
    ([name, i]) => {
      const fig = document.querySelector(`figure[aria-label="${name}"]`);
      const u = fig?.uplot;
      if (!u) return null;
      return u.data[0].map((t, k) => [t, u.data[i][k]]).filter(([, v]) => v != null);
    },
    [name, i],
  );

test("a device never ticked in the Plot was recorded from the start: ticking it draws its past", async () => {
  const opened = await page.evaluate(() => Date.now());
  await page.waitForTimeout(2500);
  const panel = await openTab(page, "Plot");
  const ticked = await page.evaluate(() => Date.now());
  await panel.getByRole("checkbox", { name: "Joint 3 · j3" }).check();
  await panel.getByRole("checkbox", { name: "Joint 1 · j1" }).uncheck();
  await page.waitForTimeout(500);
  // What the Plot holds for joint 3 (its CSV export: the rows of the window shown).
  const [download] = await Promise.all([page.waitForEvent("download"), panel.getByRole("button", { name: "Export CSV" }).click()]);
  const csv = (await readFile(await download.path(), "utf8")).trim().split("\n");
  const col = csv[0].split(",").indexOf("joint 3 position actual (deg)");
  assert.ok(col > 0, csv[0]);
  const drawn = csv.slice(1).map((r) => r.split(",")).filter((r) => r[col] !== "").map((r) => [Number(r[0]), Number(r[col])]);
  assert.ok(drawn.length > 0, "joint 3 has readings");
  assert.ok(drawn[0][0] < ticked - 2000, `the first reading (${drawn[0][0]}) is from before the tick (${ticked})`);
  assert.ok(drawn[0][0] >= opened - 1000, "and not from before the page opened");
  // What is drawn is what joint 3 reads: its last reading against whj.status through the API.
  const status = await runRequest(studio.url, { op: "whj.status", joints: "3" });
  assert.ok(Math.abs(drawn[drawn.length - 1][1] - status.results[0].position_deg) < 0.05);
  await panel.getByRole("checkbox", { name: "Joint 3 · j3" }).uncheck();
  await panel.getByRole("checkbox", { name: "Joint 1 · j1" }).check();
});

test("the history keeps a bounded ring per device", async () => {
  const r = await page.evaluate(() => {
    const ring = window.studio.history.rings.get("whj|sim-whj|5");
    const cap = ring.cap;
    for (let i = 0; i < cap * 3; i++) ring.push(1e12 + i, i, 0, 0);
    const kept = ring.since(0);
    const keys = [...window.studio.history.rings.keys()];
    return {
      cap, n: ring.n, first: kept.pos[0], last: kept.pos[kept.pos.length - 1], length: kept.t.length,
      devices: keys.filter((k) => !k.startsWith("robot|")).length,
      joints: keys.filter((k) => k.startsWith("robot|")).length,
    };
  });
  assert.equal(r.n, r.cap);
  assert.equal(r.length, r.cap);
  assert.equal(r.first, 2 * r.cap, "the oldest kept is the first not overwritten");
  assert.equal(r.last, 3 * r.cap - 1);
  assert.equal(r.cap, 65 * 50, "65 s at the highest rate offered");
  assert.equal(r.devices, 23, "one ring per device of the simulated robot: 16 servos and 7 joints");
  assert.equal(r.joints, 23, "and one per joint of its robot file");
});

test("the Device panel's mini-chart draws the joint's position as whj.status reads it", async () => {
  const panel = await openTab(page, "Device");
  await panel.getByLabel("Device", { exact: true }).selectOption({ label: "Joint 2 · j2" });
  const fig = panel.getByRole("figure", { name: "Position chart" });
  await fig.locator("canvas").waitFor();
  await until(async () => (await chartValues("Position chart", 1))?.length > 10, { what: "points in the mini-chart" });
  const drawn = await chartValues("Position chart", 1);
  const status = await runRequest(studio.url, { op: "whj.status", joints: "2" });
  assert.ok(Math.abs(drawn[drawn.length - 1][1] - status.results[0].position_deg) < 0.05);
  assert.match(await fig.textContent(), /Position chart: joint 2 position \(deg\), last 10 s/);
});

test("a wave's asked signal is drawn as its target in the Waveform's chart and the Plot", async () => {
  await arm(page);
  const panel = await openTab(page, "Waveform");
  await panel.getByLabel("Joint", { exact: true }).selectOption({ label: "Joint 1 · j1" });
  await panel.getByLabel("Amplitude (deg)").fill("8");
  await panel.getByLabel("Offset (deg)").fill("0");
  await panel.getByLabel("Frequency (Hz)").fill("0.5");
  await panel.getByLabel("Duration (s)").fill("3");
  // A sine from rest starts at once (its catch-up changes set-points by less than the
  // 0.1 deg the panel asks about).
  await panel.getByRole("button", { name: "Start wave" }).click();
  await panel.getByText(/Wave done/).waitFor({ timeout: 15_000 });
  const target = await chartValues("Wave chart", 2);
  const actual = await chartValues("Wave chart", 1);
  assert.ok(target.length > 20, `${target.length} target points`);
  const tv = target.map(([, v]) => v);
  assert.ok(Math.max(...tv) > 7.9 && Math.min(...tv) < -7.9, `the target swings ±8: ${Math.min(...tv)}..${Math.max(...tv)}`);
  const av = actual.map(([, v]) => v);
  assert.ok(Math.max(...av) > 6 && Math.min(...av) < -6, `the joint followed: ${Math.min(...av)}..${Math.max(...av)}`);
  await screenshot(page, "waveform-chart");
  await docShot(panel.locator("section", { has: page.locator("#wave-result") }), "charts");

  const plot = await openTab(page, "Plot");
  await plot.getByLabel("Window").selectOption("10");
  const [download] = await Promise.all([page.waitForEvent("download"), plot.getByRole("button", { name: "Export CSV" }).click()]);
  const csv = (await readFile(await download.path(), "utf8")).trim().split("\n");
  const cols = csv[0].split(",");
  const ti = cols.indexOf("joint 1 position target (deg)");
  const targets = csv.slice(1).map((r) => r.split(",")[ti]).filter((v) => v !== "").map(Number);
  assert.ok(Math.max(...targets) > 7.9 && Math.min(...targets) < -7.9, "the Plot's target is the wave");
  await screenshot(page, "plot-wave");
});

test("a wave 21° from the joint warns of its clamped set-points and starts only when run anyway", async () => {
  const panel = await openTab(page, "Waveform");
  await until(async () => Math.abs((await simJoint(studio.url, 1)).position_deg) < 1, { what: "joint 1 near 0" });
  await panel.getByLabel("Amplitude (deg)").fill("5");
  await panel.getByLabel("Offset (deg)").fill("21");
  await panel.getByLabel("Frequency (Hz)").fill("0.5");
  await panel.getByLabel("Duration (s)").fill("3");
  const framesBefore = await page.evaluate(() => window.studio.pending.size);
  await panel.getByRole("button", { name: "Start wave" }).click();
  const warning = panel.getByRole("alert").filter({ hasText: "set-points would be clamped" });
  await warning.waitFor({ timeout: 5000 });
  const count = Number(/(\d+) of 600 set-points would be clamped, by up to 2\d\.\d+ deg/.exec(await warning.textContent())[1]);
  assert.ok(count > 0, `${count} clamped`);
  assert.match(await panel.getByRole("status").textContent(), /Not started/);
  assert.equal(await page.evaluate(() => window.studio.pending.size), framesBefore, "nothing started");
  assert.ok(Math.abs((await simJoint(studio.url, 1)).position_deg) < 1, "the joint did not move");
  // The same plan through the API, from where the joint is, says the same.
  const at = (await runRequest(studio.url, { op: "whj.status", joints: "1" })).results[0].position_deg;
  const plan = await (await fetch(new URL("api/plan", studio.url), {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify({ op: "whj.wave", joint: 1, amplitude: 5, offset: 21, frequency: 0.5, duration: 3, rate_hz: 200, from: at }),
  })).json();
  assert.ok(plan.notes.some((n) => n.startsWith(`${count} of 600 set-point(s) clamped`)), plan.notes.join("\n"));
  assert.ok(plan.notes.some((n) => n.includes("lead-in ramp")), plan.notes.join("\n"));
  assert.match(await warning.textContent(), /lead-in ramp/);
  await screenshot(page, "waveform-clamp-warning");
  await docShot(panel.locator("section", { has: page.locator("#wave-signal") }), "clamp");

  await warning.getByRole("button", { name: "Run anyway" }).click();
  await panel.getByText(/Wave done/).waitFor({ timeout: 15_000 });
  const clamped = Number(await panel.locator('tr[data-field="clamped"] td.num').textContent());
  assert.equal(clamped, count, "the run clamped as many set-points as the warning said");
  assert.ok((await simJoint(studio.url, 1)).position_deg > 10, "the confirmed wave ran");
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
