// The Robot panel: trajectory play with its record, teaching (asked first), calibration and
// teleoperation of the built-in robot's joints by name; each done by clicking and checked
// against the same request through `robobus run`.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startStudio, launchBrowser, openPage, openTab, arm, teardown } from "./harness.mjs";
import { cliRun, docShot, flowOf } from "./cli.mjs";

let studio;
let browser;
let page;
let errors;
let panel;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  panel = await openTab(page, "Robot");
  await arm(page);
});

after(() => teardown(browser, studio));

const ids = async (table) => table.locator("tbody tr").evaluateAll((rows) => rows.map((r) => r.cells[0].textContent));

test("a trajectory played shows its record: per joint the commands and targets robobus run's play gives", async () => {
  const card = panel.getByRole("region", { name: "Trajectory play" });
  const trajectory = "time_s,j1\n0,0\n1,10\n2,0\n";
  await card.getByLabel("Trajectory", { exact: true }).fill(trajectory);
  await card.getByRole("button", { name: "Play the trajectory", exact: true }).click();
  const flow = flowOf(card, "Trajectory play");
  await flow.getByText("robot.play ran.").waitFor({ timeout: 15_000 });
  const cli = (await cliRun({ op: "robot.play", trajectory, rate_hz: 50, torque: 2 })).report;
  const table = flow.getByRole("table", { name: "Play record" });
  assert.deepEqual(await ids(table), cli.results.map((r) => r.id));
  const cells = await table.locator("tbody tr").first().locator("td").allTextContents();
  assert.equal(cells[1], String(cli.results[0].commands));
  assert.equal(cells[5], String(cli.results[0].target_deg));
  assert.match(await flow.locator('p[data-field="summary"]').textContent(), new RegExp(`ticks: ${cli.summary.ticks}`));
  await docShot(card, "robot-play");
});

test("teaching asks first (the joints go limp), records every joint, and its trajectory goes to the play form", async () => {
  const card = panel.getByRole("region", { name: "Teaching" });
  await card.getByLabel("Seconds").fill("0.3");
  await card.getByRole("button", { name: "Record a trajectory", exact: true }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  await dialog.getByRole("button", { name: "Confirm", exact: true }).click();
  const flow = flowOf(card, "Teaching");
  await flow.getByText("robot.teach ran.").waitFor({ timeout: 15_000 });
  const cli = (await cliRun({ op: "robot.teach", seconds: 0.3, rate_hz: 20, confirm: true })).report;
  assert.deepEqual(await ids(flow.getByRole("table", { name: "Teaching" })), cli.results.map((r) => r.id));
  const text = await panel.getByRole("region", { name: "Trajectory play" }).getByLabel("Trajectory", { exact: true }).inputValue();
  assert.equal(text.split("\n")[0], cli.summary.trajectory.split("\n")[0]);
});

test("a calibration without moving the joints fails each joint as robobus run's does", async () => {
  const card = panel.getByRole("region", { name: "Calibration" });
  await card.getByLabel("Seconds").fill("0.3");
  await card.getByRole("button", { name: "Run the calibration", exact: true }).click();
  const flow = flowOf(card, "Calibration");
  const cli = (await cliRun({ op: "robot.calibrate", seconds: 0.3, rate_hz: 20, zero: "keep", margin_deg: 2 })).report;
  await flow.getByText(/^robot\.calibrate (ran|failed)/).waitFor({ timeout: 15_000 });
  const table = flow.getByRole("table", { name: "Calibration" });
  assert.deepEqual(await ids(table), cli.results.map((r) => r.id));
  // Each joint fails for the same reason (where the joints rest differs: the play before moved j1).
  const why = (e) => /^joint \S+: moved through/.exec(e)?.[0] ?? e;
  const shown = await table.locator("tbody tr").evaluateAll((rows) => rows.map((r) => r.cells[r.cells.length - 1].textContent));
  assert.deepEqual(shown.map(why), cli.results.map((r) => why(r.error ?? "—")));
  assert.ok(cli.results.every((r) => r.kind));
});

test("teleoperation drives the follower from its leader for its time, as robobus run's teleop reports", async () => {
  const card = panel.getByRole("region", { name: "Teleoperation" });
  await card.getByLabel("Leader 1").selectOption("j1");
  await card.getByLabel("Follower 1").selectOption("j2");
  await card.getByLabel("Seconds").fill("0.5");
  await card.getByRole("button", { name: "Start the teleoperation", exact: true }).click();
  const flow = flowOf(card, "Teleoperation");
  await flow.getByText("robot.teleop ran.").waitFor({ timeout: 15_000 });
  const cli = (await cliRun({ op: "robot.teleop", map: [{ leader: "j1", follower: "j2", scale: 1, offset_deg: 0 }], rate_hz: 50, seconds: 0.5 })).report;
  const cells = await flow.getByRole("table", { name: "Teleoperation" }).locator("tbody tr td").allTextContents();
  assert.deepEqual(cells.slice(0, 2), [cli.results[0].id, cli.results[0].leader]);
  assert.ok(Number(cells[2]) > 0);
});

test("teleoperation takes at most 64 pairs, as robot.teleop does: a 65th is refused on the page", async () => {
  const card = panel.getByRole("region", { name: "Teleoperation" });
  const add = card.getByRole("button", { name: "Add a pair", exact: true });
  const pairs = card.locator("table.pairs tbody tr");
  // Clicked up to 64 without reading the table after each click (9.8 s -> 6.7 s), then the
  // count checked before and after the 65th.
  for (let n = await pairs.count(); n < 64; n++) await add.click();
  assert.equal(await pairs.count(), 64);
  await add.click();
  assert.equal(await pairs.count(), 64);
  await page.getByText("At most 64 leader → follower pairs (robot.teleop's bound).").waitFor();
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
