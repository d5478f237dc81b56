// The Settings panel: a Bus scan row opens its device's whole settings table, read with one
// request; values edited in place, each write through its dry run and confirmation class;
// checked against the same requests through `robobus run` and reads of the devices.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startStudio, launchBrowser, openPage, runRequest, openTab, teardown } from "./harness.mjs";
import { cliRun, recordRequests, docShot, flowOf } from "./cli.mjs";

let studio;
let browser;
let page;
let errors;
let sent;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  sent = recordRequests(page);
});

after(() => teardown(browser, studio));

async function scanAndOpen(scanName, sectionName, rowName) {
  const bus = await openTab(page, "Bus");
  const section = bus.getByRole("region", { name: sectionName });
  await section.getByRole("button", { name: scanName }).click();
  await section.getByText(/^Found \d+/).waitFor({ timeout: 20_000 });
  sent.clear();
  await section.getByRole("button", { name: rowName, exact: true }).click();
  const panel = page.getByRole("tabpanel", { name: "Settings", exact: true });
  await panel.waitFor({ state: "visible" });
  return panel;
}

test("clicking a wCK scan row opens the servo's settings: one wck.backup, its values as robobus run reads them", async () => {
  const panel = await scanAndOpen("Scan wCK bus", "wCK servos (UART)", "Open servo 3");
  const table = panel.getByRole("table", { name: "Settings of servo 3" });
  await table.waitFor();
  const cli = (await cliRun({ op: "wck.backup", id: 3 })).report.summary;
  const read = (group) => table.locator(`td[data-group="${group}"]`).textContent();
  assert.equal(await read("gains"), `P gain ${cli.p_gain}, D gain ${cli.d_gain}`);
  assert.equal(await read("i-gain"), `I gain ${cli.i_gain}`);
  assert.equal(await read("speed"), `Speed ${cli.speed}, Acceleration ${cli.accel}`);
  assert.equal(await read("overload"), `Threshold code ${cli.overload}`);
  assert.equal(await read("bounds"), `Lower bound ${cli.lower}, Upper bound ${cli.upper}`);
  // The whole table is one request (no read per row).
  const reads = sent.runs.filter((r) => r.op.startsWith("wck."));
  assert.deepEqual(reads.map((r) => r.op), ["wck.backup"]);
  assert.equal(reads[0].id, 3);
});

test("a gain edited in place shows its dry run, asks (EEPROM), and the table shows what wck.get reads back", async () => {
  const panel = page.getByRole("tabpanel", { name: "Settings", exact: true });
  const table = panel.getByRole("table", { name: "Settings of servo 3" });
  await table.getByLabel("P gain of Position gains").fill("41");
  await table.getByLabel("D gain of Position gains").fill("9");
  await table.getByRole("button", { name: "Dry run: Write Position gains", exact: true }).click();
  const flow = flowOf(panel, "Settings");
  await flow.getByText("Dry run of wck.set: nothing was sent; running it asks first.").waitFor();
  assert.match(await flow.locator('dd[data-field="confirm"]').textContent(), /EEPROM/);
  assert.notEqual((await flow.locator("pre.frames").textContent()).trim(), "");
  await table.getByRole("button", { name: "Write Position gains", exact: true }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  await dialog.getByRole("button", { name: "Cancel", exact: true }).click();
  await flow.getByText("Cancelled: nothing was sent.").waitFor();
  const untouched = await runRequest(studio.url, { op: "wck.get", param: "gains", id: 3 });
  assert.notEqual(untouched.results[0].p_gain, 41);
  await table.getByRole("button", { name: "Write Position gains", exact: true }).click();
  await dialog.waitFor();
  await dialog.getByRole("button", { name: "Confirm", exact: true }).click();
  await table.locator('td[data-group="gains"]', { hasText: "P gain 41, D gain 9" }).waitFor();
  const get = await runRequest(studio.url, { op: "wck.get", param: "gains", id: 3 });
  assert.equal(get.results[0].p_gain, 41);
  assert.equal(get.results[0].d_gain, 9);
});

test("clicking a WHJ scan row opens every setting of the joint in one whj.backup, as robobus run reads them", async () => {
  const panel = await scanAndOpen("Scan WHJ bus", "WHJ joints (CAN FD)", "Open joint 2");
  const table = panel.getByRole("table", { name: "Settings of joint 2" });
  await table.waitFor();
  const cli = (await cliRun({ op: "whj.backup", joint: 2 })).report.summary.settings;
  const rows = table.locator("tbody tr");
  assert.equal(await rows.count(), cli.length);
  for (const s of cli) {
    const cell = table.locator(`td[data-register="${s.register}"]`);
    const want = s.value != null ? `(raw ${s.raw})` : `raw ${s.raw}`;
    assert.ok((await cell.textContent()).endsWith(want), `${s.register}: ${await cell.textContent()} vs ${want}`);
  }
  const reads = sent.runs.filter((r) => r.op.startsWith("whj.") && r.op !== "whj.registers");
  assert.deepEqual(reads.map((r) => r.op), ["whj.backup"]);
});

test("a plain register is written at once; a register of the confirm class needs the confirm step", async () => {
  const panel = page.getByRole("tabpanel", { name: "Settings", exact: true });
  const table = panel.getByRole("table", { name: "Settings of joint 2" });
  await table.getByLabel("New value of LIT_MAX_ACC").fill("450");
  await table.getByRole("button", { name: "Write LIT_MAX_ACC", exact: true }).click();
  await table.locator('td[data-register="LIT_MAX_ACC"]', { hasText: "(raw 4500)" }).waitFor();
  assert.equal(await page.getByRole("dialog").count(), 0);
  const acc = await runRequest(studio.url, { op: "whj.read", joints: "2", register: "LIT_MAX_ACC" });
  assert.equal(acc.results[0].raw, 4500);

  const before = await runRequest(studio.url, { op: "whj.read", joints: "2", register: "SYS_ENABLE_ON_POWER" });
  const flipped = 1 - before.results[0].raw;
  await table.getByLabel("New value of SYS_ENABLE_ON_POWER").fill(String(flipped));
  await table.getByRole("button", { name: "Write SYS_ENABLE_ON_POWER", exact: true }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  assert.match(await dialog.textContent(), /power-up/);
  await dialog.getByRole("button", { name: "Confirm", exact: true }).click();
  await table.locator('td[data-register="SYS_ENABLE_ON_POWER"]', { hasText: `raw ${flipped}` }).waitFor();
  const after = await runRequest(studio.url, { op: "whj.read", joints: "2", register: "SYS_ENABLE_ON_POWER" });
  assert.equal(after.results[0].raw, flipped);
  await panel.getByRole("group", { name: "Live status" }).getByText("position:").waitFor();
  await docShot(panel, "settings");
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
