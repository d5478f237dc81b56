// A lesson without surprises: a silent device is flagged in the header whichever tab is
// open (and the flag opens it in Device); robot poses by the robot file's joint names, any
// set of them, wCK servos and WHJ joints together: recorded as robot.sample reads them,
// gone to, and played in a loop, the Plot drawing their trajectory as the joints' target.
// (The stop key stopping a running wave, and the header
// staying on screen: arming.test.mjs.)

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { readFile } from "node:fs/promises";
import { startStudio, launchBrowser, openPage, runRequest, simState, screenshot, openTab, arm, teardown, until } from "./harness.mjs";
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

const flag = () => page.locator("#silent-state");

test("a servo that goes silent is flagged in the header while another tab is open", async () => {
  await openTab(page, "Waveform");
  await page.waitForTimeout(1000);
  assert.equal(await flag().isVisible(), false, "nothing silent at first");
  // Servo 2 moves to ID 26: nothing answers at ID 2 any more.
  await page.evaluate(() => window.studio.run({ op: "wck.set-id", id: 2, new_id: 26, confirm: true }));
  await until(async () => (await flag().isVisible()) && /silent: servo 2 · s2/.test(await flag().textContent()), { what: "the flag", timeout: 5000 });
  assert.equal(await page.getByRole("tabpanel", { name: "Waveform" }).isVisible(), true, "still on Waveform");
  // What the flag says is what the same reading through the API says.
  const status = await runRequest(studio.url, { op: "wck.status", ids: "2" });
  assert.equal(status.results[0].kind, "no-device");
  await screenshot(page, "header-silent");
  await docShot(page.locator("header.top"), "header");
  // The flag opens the silent servo in Device.
  await flag().click();
  const device = page.getByRole("tabpanel", { name: "Device" });
  await device.waitFor({ state: "visible" });
  assert.equal(await device.getByLabel("Device", { exact: true }).inputValue(), "wck|sim-wck|2");
  await until(async () => (await device.getByLabel("Position (steps)").textContent()) === "no reply", { what: "no reply in Device" });
  // Back at its ID, it answers and the flag goes.
  await page.evaluate(() => window.studio.run({ op: "wck.set-id", id: 26, new_id: 2, confirm: true }));
  await until(async () => !(await flag().isVisible()), { what: "the flag gone", timeout: 5000 });
});

const poses = () => page.getByRole("tabpanel", { name: "Poses" });
const rpStatus = () => page.locator("#robot-poses-status").textContent();

test("a robot pose of any joints, both families, records what robot.sample reads", async () => {
  const panel = await openTab(page, "Poses");
  const joints = panel.getByRole("group", { name: "Joints of the pose" });
  // Only s3, s5 (wCK) and j2, j4 (WHJ): not 0..N-1, and both families.
  for (const b of await joints.getByRole("checkbox").all()) await b.uncheck();
  for (const name of ["s3", "s5", "j2", "j4"]) await joints.getByRole("checkbox", { name, exact: true }).check();
  const sample = await runRequest(studio.url, { op: "robot.sample" });
  await panel.getByRole("button", { name: "Record robot pose" }).click();
  await until(async () => /Recorded pose 1: 4 joints/.test(await rpStatus()), { what: "the record" });
  const table = panel.getByRole("table", { name: "Robot poses" });
  const headers = await table.locator("thead th").allTextContents();
  assert.deepEqual(headers, ["#", "Pose", "Transition (s)", "Hold (s)", "s3 (deg)", "s5 (deg)", "j2 (deg)", "j4 (deg)", "Actions"]);
  for (const name of ["s3", "s5", "j2", "j4"]) {
    const v = Number(await panel.getByLabel(`${name} of pose 1 (deg)`).inputValue());
    const want = sample.results.find((r) => r.id === name).position_deg;
    assert.ok(Math.abs(v - want) < 1.1, `${name}: ${v} recorded, ${want} read`);
  }
});

test("go to a pose moves the joints of both families there; the list plays in a loop", async () => {
  const panel = poses();
  await arm(page);
  // Pose 2: the same joints, edited to where they should go.
  await panel.getByRole("button", { name: "Record robot pose" }).click();
  await until(async () => /Recorded pose 2/.test(await rpStatus()), { what: "pose 2" });
  const set = async (label, v) => {
    await panel.getByLabel(label).fill(String(v));
    await panel.getByLabel(label).press("Tab");
  };
  await set("s3 of pose 2 (deg)", 20);
  await set("s5 of pose 2 (deg)", -15);
  await set("j2 of pose 2 (deg)", 10);
  await set("j4 of pose 2 (deg)", -8);
  await set("Transition of pose 2 (s)", 0.6);
  await panel.getByRole("button", { name: "Go to pose 2" }).click();
  await until(async () => /^Done: pose 2/.test(await rpStatus()), { what: "go to pose 2", timeout: 15_000 });
  // The joints settle at the pose, as robot.sample reads them through the API.
  const want = { s3: 20, s5: -15, j2: 10, j4: -8 };
  let sample;
  const at = () => Object.fromEntries(Object.keys(want).map((n) => [n, sample.results.find((r) => r.id === n).position_deg]));
  const near = () => Object.entries(at()).every(([n, v]) => Math.abs(v - want[n]) < (n[0] === "s" ? 1.5 : 0.3));
  await until(async () => {
    sample = await runRequest(studio.url, { op: "robot.sample" });
    return near();
  }, { what: "the joints at pose 2", timeout: 5000 });
  const untouched = (await simState(studio.url)).whj.find((j) => j.id === 3);
  assert.ok(Math.abs(untouched.position_deg) < 0.5, "a joint not in the pose stays");

  // Both poses, twice: the trajectory robot.play plays, saved as the CLI reads it.
  await panel.getByLabel("Loops").fill("2");
  const [download] = await Promise.all([page.waitForEvent("download"), panel.getByRole("button", { name: "Save trajectory" }).click()]);
  const text = await readFile(await download.path(), "utf8");
  const lines = text.trim().split("\n");
  assert.equal(lines[0], "time_s,s3,s5,j2,j4");
  assert.equal(lines.length, 1 + 8, "two poses, each held, two loops");
  assert.deepEqual(lines.slice(1).map((l) => Number(l.split(",")[0])), [0, 0.5, 1.1, 1.6, 2.6, 3.1, 3.7, 4.2]);
  assert.deepEqual(lines[3].split(",").slice(1).map(Number), [20, -15, 10, -8], "pose 2 as edited");
  await panel.getByRole("button", { name: "Play poses" }).click();
  await until(async () => /^Done: 2 poses × 2/.test(await rpStatus()), { what: "the loops", timeout: 20_000 });
  await until(async () => {
    sample = await runRequest(studio.url, { op: "robot.sample" });
    return near();
  }, { what: "the joints back at pose 2, the last", timeout: 5000 });
  await screenshot(page, "poses-robot");
  await docShot(panel.locator("section", { has: page.locator("#robot-poses") }), "poses");

  // The Plot draws the poses' trajectory as the joints' target, against what they read.
  const plot = await openTab(page, "Plot");
  await plot.getByRole("checkbox", { name: "Robot joint j2", exact: true }).check();
  await plot.getByRole("checkbox", { name: "Joint 1 · j1" }).uncheck();
  const [csvFile] = await Promise.all([page.waitForEvent("download"), plot.getByRole("button", { name: "Export CSV" }).click()]);
  const csv = (await readFile(await csvFile.path(), "utf8")).trim().split("\n");
  const cols = csv[0].split(",");
  const ti = cols.indexOf("robot j2 position target (deg)");
  const ai = cols.indexOf("robot j2 position actual (deg)");
  assert.ok(ti > 0 && ai > 0, csv[0]);
  const targets = csv.slice(1).map((r) => r.split(",")[ti]).filter((v) => v !== "").map(Number);
  const actual = csv.slice(1).map((r) => r.split(",")[ai]).filter((v) => v !== "").map(Number);
  assert.ok(targets.some((v) => Math.abs(v - 10) < 0.01) && targets.some((v) => Math.abs(v) < 0.5), `the target goes between the poses: ${Math.min(...targets)}..${Math.max(...targets)}`);
  assert.ok(actual.length > 20 && Math.max(...actual) > 9 && Math.min(...actual) < 1, `j2 followed: ${Math.min(...actual)}..${Math.max(...actual)}`);
  await screenshot(page, "plot-poses");
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
