// The Preview panel: a request's dry run shows the exact bytes the server plans, its effect
// and its confirmation class; "Run it" sends it (refused while disarmed for motion, a
// confirmation dialog for an EEPROM write); a teleoperation runs from it; bad JSON is
// pointed at; other panels open it.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startStudio, launchBrowser, openPage, simServo, runRequest, screenshot, openTab, arm, teardown, until } from "./harness.mjs";

let studio;
let browser;
let page;
let errors;
let panel;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  await page.waitForFunction(() => window.studio.state.controller === true);
  panel = await openTab(page, "Preview");
});

after(() => teardown(browser, studio));

const status = () => panel.getByRole("status").textContent();
const fact = (name) => panel.locator(`dd[data-field="${name}"]`).textContent();

async function plan(request) {
  const res = await fetch(new URL("api/plan", studio.url), {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify(request),
  });
  assert.equal(res.status, 200);
  return res.json();
}

test("the dry run of a move shows its packet, its effect and no confirmation", async () => {
  const request = { op: "wck.move", id: 2, position: 200, torque: 0 };
  await panel.getByLabel("Request (JSON)").fill(JSON.stringify(request));
  await panel.getByRole("button", { name: "Show dry run" }).click();
  await until(async () => /Dry run of wck\.move: nothing was sent/.test(await status()), { what: "the dry run" });
  const frames = await panel.getByLabel("Dry run: bytes and frames").textContent();
  assert.equal(frames, (await plan(request)).text);
  assert.match(frames, /^FF 02 C8 4A$/m);
  assert.match(await fact("effect"), /^motion/);
  assert.match(await fact("confirm"), /^none/);
  assert.equal(await fact("steps"), "1");
  await screenshot(page, "preview");
});

test("Run it: refused while disarmed, then sent once armed", async () => {
  await panel.getByRole("button", { name: "Run it" }).click();
  await until(async () => /wck\.move failed: refused/.test(await status()), { what: "the refusal" });
  assert.equal((await simServo(studio.url, 2)).position, 127);
  await arm(page);
  await panel.getByRole("button", { name: "Run it" }).click();
  await until(async () => /^wck\.move ran\.$/.test(await status()), { what: "the run" });
  const report = JSON.parse(await panel.getByLabel("Report").textContent());
  assert.equal(report.op, "wck.move");
  assert.equal(report.results[0].position_before, 127);
  await until(async () => Math.abs((await simServo(studio.url, 2)).position - 200) <= 2, { timeout: 3000, what: "servo 2 at 200" });
});

test("an EEPROM write shows its confirmation class and asks before it runs", async () => {
  const request = { op: "wck.set", param: "gains", id: 4, p: 33, d: 12 };
  await panel.getByLabel("Request (JSON)").fill(JSON.stringify(request));
  await panel.getByRole("button", { name: "Show dry run" }).click();
  await until(async () => /Dry run of wck\.set/.test(await status()), { what: "the dry run" });
  assert.match(await fact("confirm"), /^non-volatile: .*non-volatile memory/);
  assert.match(await fact("effect"), /^configure/);
  await panel.getByRole("button", { name: "Run it" }).click();
  const dialog = page.getByRole("dialog");
  await dialog.getByRole("button", { name: "Cancel" }).click();
  await until(async () => /Cancelled: nothing was sent/.test(await status()), { what: "the cancel" });
  const gains = await runRequest(studio.url, { op: "wck.get", param: "gains", id: 4 });
  assert.notEqual(gains.results[0].p_gain, 33);

  await panel.getByRole("button", { name: "Run it" }).click();
  await dialog.getByRole("button", { name: "Confirm" }).click();
  await until(async () => /^wck\.set ran\.$/.test(await status()), { what: "the write" });
  const after = await runRequest(studio.url, { op: "wck.get", param: "gains", id: 4 });
  assert.equal(after.results[0].p_gain, 33);
});

test("a teleoperation runs from the preview: the follower goes where the leader is, 20° on", async () => {
  const request = {
    op: "robot.teleop",
    map: [{ leader: "s0", follower: "s6", offset_deg: 20 }],
    seconds: 1,
    rate_hz: 20,
    passive_leader: false,
  };
  await panel.getByLabel("Request (JSON)").fill(JSON.stringify(request));
  await panel.getByRole("button", { name: "Show dry run" }).click();
  await until(async () => /Dry run of robot\.teleop/.test(await status()), { what: "the dry run" });
  assert.match(await fact("effect"), /^motion/);
  assert.match(await panel.getByLabel("Dry run: bytes and frames").textContent(), /s6 ← s0 × 1 \+ 20°/);
  await panel.getByRole("button", { name: "Run it" }).click();
  await until(async () => /^robot\.teleop ran\.$/.test(await status()), { timeout: 15000, what: "the run" });
  const report = JSON.parse(await panel.getByLabel("Report").textContent());
  const row = report.results[0];
  assert.equal(row.id, "s6");
  assert.equal(row.leader, "s0");
  assert.equal(row.failed, 0);
  assert.equal(report.summary.leader_lost, false);
  assert.equal(report.summary.held, 0);
  assert.ok(row.commands >= 15, JSON.stringify(report));
  // 20° is 19 steps of 1.055°: the follower is there, within a step.
  const s0 = (await simServo(studio.url, 0)).position;
  await until(async () => Math.abs((await simServo(studio.url, 6)).position - (s0 + 19)) <= 1, {
    timeout: 3000,
    what: `servo 6 at ${s0 + 19}`,
  });
});

test("bad JSON is pointed at and nothing is asked of the server", async () => {
  const editor = panel.getByLabel("Request (JSON)");
  await editor.fill('{"op": "wck.status",\n "ids": }');
  await panel.getByRole("button", { name: "Show dry run" }).click();
  await until(async () => /^Not a request \(line 2, column 9\)/.test(await status()), { what: "the JSON error" });
  const at = '{"op": "wck.status",\n "ids": '.length;
  assert.deepEqual(await editor.evaluate((t) => [t.selectionStart, document.activeElement === t]), [at, true]);
});

test("a request the library refuses shows its message", async () => {
  await panel.getByLabel("Request (JSON)").fill('{"op": "wck.move", "id": 2, "position": 300}');
  await panel.getByRole("button", { name: "Show dry run" }).click();
  await until(async () => /Dry run refused \(bad-input\)/.test(await status()), { what: "the refusal" });
  assert.equal(await panel.getByLabel("Dry run: bytes and frames").textContent(), "");
});

test("another panel opens the preview with its request", async () => {
  await openTab(page, "Poses");
  await page.getByRole("tabpanel", { name: "Poses" }).getByLabel("Load keyframe file")
    .setInputFiles({ name: "m.txt", mimeType: "text/plain", buffer: Buffer.from("pose 200 100 110\n") });
  await page.getByText("Loaded m.txt").waitFor();
  await page.getByRole("button", { name: "Show dry run of the scene" }).click();
  await panel.waitFor({ state: "visible" });
  await until(async () => /Dry run of wck\.play/.test(await status()), { what: "the scene's dry run" });
  const json = JSON.parse(await panel.getByLabel("Request (JSON)").inputValue());
  assert.equal(json.op, "wck.play");
  assert.match(json.motion, /pose 200 100 110/);
  assert.match(await panel.getByLabel("Dry run: bytes and frames").textContent(), /^FF 1F 02 64 6E/m);
});

test("no console errors but the expected 400 and 409 answers", () => {
  // Chromium logs every non-2xx answer of fetch() as a console error: here the refused
  // move (409) and the out-of-range plan (400).
  const expected = errors.filter((e) => /status of (400 \(Bad Request\)|409 \(Conflict\))/.test(e));
  assert.equal(expected.length, 2, errors.join("\n"));
  assert.deepEqual(errors.filter((e) => !expected.includes(e)), []);
});
