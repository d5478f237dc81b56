// The Poses panel (motion builder): a keyframe file loads (a bad one is pointed at by line
// and column), the scene plays and moves the simulated servos, a recorded pose holds the
// servos' positions, rows are edited, reordered and deleted, "Save file" writes the CLI's
// keyframe format, and "Make passive" releases the servos.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { readFile } from "node:fs/promises";
import { startStudio, launchBrowser, openPage, simState, runRequest, screenshot, openTab, arm, teardown, until } from "./harness.mjs";

let studio;
let browser;
let page;
let errors;
let panel;

const SCENE = "# four servos\ntorque 1\npose 300 127 127 127 127\npose 400 100 150 110 140\nhold 100\n";

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  await page.waitForFunction(() => window.studio.state.controller === true);
  panel = await openTab(page, "Poses");
});

after(() => teardown(browser, studio));

const status = () => panel.getByRole("status").textContent();
const file = (name, text) => ({ name, mimeType: "text/plain", buffer: Buffer.from(text) });
const rows = () => panel.getByRole("table", { name: "Scene" }).locator("tbody tr");

test("a bad keyframe file is shown at its line and column, and not loaded", async () => {
  assert.equal(await panel.getByLabel("Servos", { exact: true }).inputValue(), "0-15");
  await panel.getByLabel("Load keyframe file").setInputFiles(file("bad.txt", "torque 0\npose 300 127 127 127 127\npose 400 60 200 90 999\n"));
  await until(async () => /bad\.txt: line 3, column 20: position 999 is out of range/.test(await status()), { what: "the error" });
  assert.match(await rows().first().textContent(), /No poses yet/);
});

test("a keyframe file loads into the scene and plays on the simulated servos", async () => {
  await panel.getByLabel("Load keyframe file").setInputFiles(file("wave.txt", SCENE));
  await until(async () => /Loaded wave\.txt: 3 steps, servos 0 to 3/.test(await status()), { what: "the load" });
  assert.equal(await rows().count(), 3);
  assert.equal(await panel.getByLabel("Servos", { exact: true }).inputValue(), "0-3");
  assert.equal(await panel.getByLabel("Torque").inputValue(), "1");
  assert.equal(await panel.getByLabel("Positions of step 2").inputValue(), "100 150 110 140");
  assert.equal(await panel.getByLabel("Transition time of step 2 (ms)").inputValue(), "400");

  assert.equal(await panel.getByRole("button", { name: "Play scene" }).isDisabled(), true, "disarmed");
  await arm(page);
  await panel.getByRole("button", { name: "Play scene" }).click();
  await until(async () => /Played: \d+ moves/.test(await status()), { timeout: 10_000, what: "the play" });
  assert.match(await status(), /last pose 100 150 110 140/);
  await until(async () => {
    const wck = (await simState(studio.url)).wck;
    return [100, 150, 110, 140].every((p, i) => Math.abs(wck[i].position - p) <= 2);
  }, { timeout: 3000, what: "servos 0-3 at the last pose" });
});

test("the scene's poses are the servos' target in the Plot, against what they read", async () => {
  const plot = await openTab(page, "Plot");
  await plot.getByRole("checkbox", { name: "Servo 1 · s1" }).check();
  await plot.getByRole("checkbox", { name: "Joint 1 · j1" }).uncheck();
  const [file] = await Promise.all([page.waitForEvent("download"), plot.getByRole("button", { name: "Export CSV" }).click()]);
  const csv = (await readFile(await file.path(), "utf8")).trim().split("\n");
  const cols = csv[0].split(",");
  const ti = cols.indexOf("servo 1 position target (deg)");
  const ai = cols.indexOf("servo 1 position actual (deg)");
  assert.ok(ti > 0 && ai > 0, csv[0]);
  const deg = (steps) => (steps * 269) / 255;
  const targets = csv.slice(1).map((r) => r.split(",")[ti]).filter((v) => v !== "").map(Number);
  assert.ok(targets.some((v) => Math.abs(v - deg(127)) < 0.01), "the first pose, 127 steps");
  assert.ok(targets.some((v) => Math.abs(v - deg(150)) < 0.01), "the second, 150 steps");
  const status = await runRequest(studio.url, { op: "wck.status", ids: "1" });
  const actual = csv.slice(1).map((r) => r.split(",")[ai]).filter((v) => v !== "").map(Number);
  assert.ok(Math.abs(actual[actual.length - 1] - status.results[0].degrees) < 1.1, `the last reading ${actual[actual.length - 1]} is wck.status's ${status.results[0].degrees}`);
  await plot.getByRole("checkbox", { name: "Servo 1 · s1" }).uncheck();
  await plot.getByRole("checkbox", { name: "Joint 1 · j1" }).check();
  await openTab(page, "Poses");
});

test("Record pose adds the servos' positions; rows are edited, reordered and deleted", async () => {
  const status0 = await runRequest(studio.url, { op: "wck.status", ids: "0-3" });
  await panel.getByRole("button", { name: "Record pose" }).click();
  await until(async () => /Recorded step 4/.test(await status()), { what: "the record" });
  const recorded = (await panel.getByLabel("Positions of step 4").inputValue()).split(" ").map(Number);
  assert.deepEqual(recorded, status0.results.map((r) => r.position));

  await panel.getByLabel("Transition time of step 4 (ms)").fill("250");
  await panel.getByLabel("Transition time of step 4 (ms)").press("Tab");
  await panel.getByRole("button", { name: "Move step 4 up" }).click();
  assert.equal(await panel.getByLabel("Transition time of step 3 (ms)").inputValue(), "250");
  await panel.getByRole("button", { name: "Delete step 1" }).click();
  assert.equal(await rows().count(), 3);
  await screenshot(page, "poses");

  const [download] = await Promise.all([
    page.waitForEvent("download"),
    panel.getByRole("button", { name: "Save file" }).click(),
  ]);
  const text = await readFile(await download.path(), "utf8");
  assert.equal(
    text,
    `# robobus keyframe motion\n# servos 0 1 2 3\ntorque 1\npose 400 100 150 110 140\npose 250 ${recorded.join(" ")}\nhold 100\n`,
  );
  // The library's parser takes it (what `robobus wck play` would play).
  const res = await fetch(new URL("api/plan", studio.url), {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify({ op: "wck.play", motion: text }),
  });
  assert.equal(res.status, 200);
});

test("Make passive releases the chosen servos", async () => {
  const before = (await simState(studio.url)).wck.slice(0, 4).map((s) => s.mode);
  assert.ok(before.every((m) => m !== "passive"), `played servos hold: ${before}`);
  await panel.getByRole("button", { name: "Make passive" }).click();
  await until(async () => /Servos 0-3 are passive/.test(await status()), { what: "passive" });
  const wck = (await simState(studio.url)).wck;
  assert.deepEqual(wck.slice(0, 4).map((s) => s.mode), ["passive", "passive", "passive", "passive"]);
});

test("a scene the library refuses is shown at its step", async () => {
  await panel.getByRole("button", { name: "Clear scene" }).click();
  await panel.getByRole("button", { name: "Add hold" }).click();
  await panel.getByRole("button", { name: "Record pose" }).click();
  await until(async () => /Recorded step 2/.test(await status()), { what: "the record" });
  await panel.getByRole("button", { name: "Play scene" }).click();
  await until(async () => /^Step 1: `hold` needs a pose before it/.test(await status()), { what: "the refusal" });
});

test("no console errors but the one expected 400 (the bad file's check)", () => {
  // Chromium logs every non-2xx answer of fetch() as a console error.
  const bad = errors.filter((e) => /status of 400 \(Bad Request\)/.test(e));
  assert.equal(bad.length, 1, errors.join("\n"));
  assert.deepEqual(errors.filter((e) => !bad.includes(e)), []);
});
