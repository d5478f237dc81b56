// The Tune panel: wCK parameters read and written (runtime and EEPROM), WHJ registers
// read and written; checked with reads of the devices.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startStudio, launchBrowser, openPage, runRequest, screenshot, openTab, teardown, until } from "./harness.mjs";

let studio;
let browser;
let page;
let errors;
let panel;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  panel = await openTab(page, "Tune");
});

after(() => teardown(browser, studio));

test("reading a wCK servo fills in its EEPROM values", async () => {
  const wck = panel.getByRole("region", { name: "wCK servo settings" });
  await wck.getByLabel("Servo", { exact: true }).selectOption({ index: 1 });
  const id = Number((await wck.getByLabel("Servo", { exact: true }).inputValue()).split("|")[2]);
  await wck.getByRole("button", { name: "Read servo settings" }).click();
  await wck.getByText(`Read servo ${id} at`).waitFor();
  const get = await runRequest(studio.url, { op: "wck.get", param: "gains", id });
  assert.equal(await wck.getByLabel("P gain", { exact: true }).inputValue(), String(get.results[0].p_gain));
  assert.equal(await wck.getByLabel("D gain", { exact: true }).inputValue(), String(get.results[0].d_gain));
  assert.notEqual(await wck.getByLabel("Acceleration", { exact: true }).inputValue(), "");
  assert.notEqual(await wck.getByLabel("Upper bound (steps)", { exact: true }).inputValue(), "");
});

test("an EEPROM gain write asks first, then wck.get shows it", async () => {
  const wck = panel.getByRole("region", { name: "wCK servo settings" });
  const id = Number((await wck.getByLabel("Servo", { exact: true }).inputValue()).split("|")[2]);
  await wck.getByLabel("P gain", { exact: true }).fill("33");
  await wck.getByLabel("D gain", { exact: true }).fill("12");
  await wck.getByRole("button", { name: "Write Position gains to EEPROM" }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  assert.match(await dialog.textContent(), /EEPROM|non-volatile/);
  await screenshot(page, "tune-confirm");
  await dialog.getByRole("button", { name: "Confirm" }).click();
  await wck.getByText("Position gains written to EEPROM").waitFor();
  const get = await runRequest(studio.url, { op: "wck.get", param: "gains", id });
  assert.equal(get.results[0].p_gain, 33);
  assert.equal(get.results[0].d_gain, 12);
});

test("a runtime gain write needs no confirmation and shows apart", async () => {
  const wck = panel.getByRole("region", { name: "wCK servo settings" });
  await wck.getByLabel("P gain", { exact: true }).fill("40");
  await wck.getByRole("button", { name: "Write Position gains (runtime)" }).click();
  await wck.getByText("Position gains written at runtime").waitFor();
  assert.equal(await page.getByRole("dialog").count(), 0);
  const gains = wck.getByRole("group", { name: "Position gains" });
  assert.match(await gains.textContent(), /Runtime \(written here\)P gain: 40/);
  assert.match(await gains.textContent(), /EEPROM \(read\)P gain: 33/);
});

test("the WHJ register table: read a register, write a plain one", async () => {
  const whj = panel.getByRole("region", { name: "WHJ joint registers" });
  const table = whj.getByRole("table", { name: "WHJ registers" });
  await table.waitFor();
  assert.ok((await table.locator("tbody tr").count()) > 50);
  await whj.getByRole("button", { name: "Read SYS_VOLTAGE" }).click();
  await whj.getByText(/SYS_VOLTAGE \(0x05\) = 24 V/).waitFor();
  await whj.getByLabel("Register", { exact: true }).fill("SEV_POSITION_P");
  await whj.getByText(/safety class: plain/).waitFor();
  await whj.getByLabel(/^Value \(/).fill("123");
  await whj.getByRole("button", { name: "Write register" }).click();
  await whj.getByText(/Wrote joint 1 SEV_POSITION_P; read back raw 123/).waitFor();
  const read = await runRequest(studio.url, { op: "whj.read", joints: "1", register: "SEV_POSITION_P" });
  assert.equal(read.results[0].raw, 123);
  await screenshot(page, "tune");
});

test("a register of the confirm class asks first; Cancel writes nothing", async () => {
  const whj = panel.getByRole("region", { name: "WHJ joint registers" });
  const before = await runRequest(studio.url, { op: "whj.read", joints: "1", register: "SYS_ENABLE_ON_POWER" });
  await whj.getByLabel("Register", { exact: true }).fill("SYS_ENABLE_ON_POWER");
  await whj.getByText(/safety class: confirm/).waitFor();
  await whj.getByLabel(/^Value \(/).fill(String(1 - before.results[0].raw));
  await whj.getByRole("button", { name: "Write register" }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  await dialog.getByRole("button", { name: "Cancel" }).click();
  await whj.getByText("Cancelled: nothing was written.").waitFor();
  const after = await runRequest(studio.url, { op: "whj.read", joints: "1", register: "SYS_ENABLE_ON_POWER" });
  assert.equal(after.results[0].raw, before.results[0].raw);
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
