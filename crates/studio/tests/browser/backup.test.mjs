// The Backup panel: a device backed up to a downloaded file, a file uploaded and compared
// with a device, restored into another device (asked first), a device compared with
// another; checked against the same requests through `robobus run` and reads of the devices.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { readFile } from "node:fs/promises";
import { startStudio, launchBrowser, openPage, runRequest, openTab, teardown } from "./harness.mjs";
import { cliRun, docShot, flowOf } from "./cli.mjs";

let studio;
let browser;
let page;
let errors;
let panel;
let flow;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  panel = await openTab(page, "Backup");
  flow = flowOf(panel, "Backup");
});

after(() => teardown(browser, studio));

const device = (value) => panel.getByLabel("Backup device").selectOption(value);

test("a servo backed up downloads the settings file robobus run wck.backup writes", async () => {
  await device("wck|sim-wck|2");
  await panel.getByRole("button", { name: "Back up the device", exact: true }).click();
  await flow.getByText("wck.backup ran.").waitFor();
  assert.match(await flow.locator('dd[data-field="effect"]').textContent(), /^read/);
  const [download] = await Promise.all([page.waitForEvent("download"), panel.getByRole("button", { name: "Download the file", exact: true }).click()]);
  assert.equal(download.suggestedFilename(), "servo-2-sim-wck.settings.json");
  const file = JSON.parse(await readFile(await download.path(), "utf8"));
  const cli = (await cliRun({ op: "wck.backup", id: 2 })).report.summary;
  assert.deepEqual(file, cli);
});

test("an uploaded file is compared with a servo as wck.diff says, restored after the EEPROM confirmation, and the servo then matches it", async () => {
  const base = (await cliRun({ op: "wck.backup", id: 4 })).report.summary;
  const wanted = { ...base, servo: 4, p_gain: 44, d_gain: 7, upper: 200 };
  const text = JSON.stringify(wanted, null, 2);
  await panel.getByLabel("Upload a settings file").setInputFiles({ name: "wanted.settings.json", mimeType: "application/json", buffer: Buffer.from(text) });
  await panel.getByText(/^Settings file: wanted.settings.json \(wCK servo/).waitFor();
  await device("wck|sim-wck|4");
  await panel.getByLabel("Compare with").selectOption("file");
  await panel.getByRole("button", { name: "Diff the device", exact: true }).click();
  await flow.getByText("wck.diff ran.").waitFor();
  const cli = (await cliRun({ op: "wck.diff", id: 4, settings: text })).report;
  const shown = flow.getByRole("table", { name: "Differences" }).locator("tbody tr");
  assert.equal(await shown.count(), cli.results.length);
  for (const [i, r] of cli.results.entries()) {
    assert.deepEqual(await shown.nth(i).locator("td").allTextContents(), [r.setting, r.a, r.b]);
  }
  assert.equal(await flow.locator('p[data-field="differ"]').textContent(), `${cli.summary.differ} settings differ from ${cli.summary.with}.`);
  await docShot(panel, "backup");

  await panel.getByRole("button", { name: "Restore into the device", exact: true }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  assert.match(await dialog.textContent(), /EEPROM|non-volatile/);
  await dialog.getByRole("button", { name: "Confirm", exact: true }).click();
  await flow.getByText("wck.restore ran.").waitFor();
  const after = await runRequest(studio.url, { op: "wck.diff", id: 4, settings: text });
  assert.deepEqual(after.results, []);
  const back = (await runRequest(studio.url, { op: "wck.backup", id: 4 })).summary;
  assert.deepEqual([back.p_gain, back.d_gain, back.upper], [44, 7, 200]);
});

test("a servo compared with another servo shows wck.diff's rows for the pair", async () => {
  await device("wck|sim-wck|4");
  await panel.getByLabel("Compare with").selectOption("other");
  await panel.getByLabel("Other device", { exact: true }).selectOption("wck|sim-wck|5");
  await panel.getByRole("button", { name: "Diff the device", exact: true }).click();
  await flow.getByText("wck.diff ran.").waitFor();
  const want = await runRequest(studio.url, { op: "wck.diff", id: 4, other: 5 });
  assert.ok(want.results.length > 0);
  const shown = flow.getByRole("table", { name: "Differences" }).locator("tbody tr");
  assert.equal(await shown.count(), want.results.length);
  for (const [i, r] of want.results.entries()) {
    assert.deepEqual(await shown.nth(i).locator("td").allTextContents(), [r.setting, r.a, r.b]);
  }
});

test("another servo copied into a servo: its backup, then the restore of that file after the EEPROM confirmation; the two then do not differ", async () => {
  await device("wck|sim-wck|5");
  await panel.getByLabel("Compare with").selectOption("other");
  await panel.getByLabel("Other device", { exact: true }).selectOption("wck|sim-wck|4");
  await panel.getByRole("button", { name: "Copy the other device into the device", exact: true }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  await dialog.getByRole("button", { name: "Confirm" }).click();
  await flow.getByText("wck.restore ran.").waitFor();
  assert.match(await panel.locator('[data-field="file"]').textContent(), /^Settings file: servo-4-sim-wck.settings.json/);
  const diff = await runRequest(studio.url, { op: "wck.diff", id: 5, other: 4 });
  assert.deepEqual(diff.results, []);
});

test("a joint backed up and compared with another: the file is robobus run whj.backup's, the diff whj.diff's", async () => {
  await device("whj|sim-whj|1");
  await panel.getByRole("button", { name: "Back up the device", exact: true }).click();
  await flow.getByText("whj.backup ran.").waitFor();
  const [download] = await Promise.all([page.waitForEvent("download"), panel.getByRole("button", { name: "Download the file", exact: true }).click()]);
  const text = await readFile(await download.path(), "utf8");
  assert.deepEqual(JSON.parse(text), (await cliRun({ op: "whj.backup", joint: 1 })).report.summary);
  await device("whj|sim-whj|2");
  await panel.getByLabel("Compare with").selectOption("file");
  await panel.getByRole("button", { name: "Diff the device", exact: true }).click();
  await flow.getByText("whj.diff ran.").waitFor();
  const cli = (await cliRun({ op: "whj.diff", joint: 2, settings: text })).report;
  const shown = flow.getByRole("table", { name: "Differences" }).locator("tbody tr");
  assert.equal(await shown.count(), cli.results.length);
  for (const [i, r] of cli.results.entries()) {
    assert.equal(await shown.nth(i).locator("td").first().textContent(), r.register);
  }
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
