// The Bus panel: scans of both families with progress and Stop, and ID / bit-rate changes
// through the confirmation dialog, checked against the simulators.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startStudio, launchBrowser, openPage, simState, screenshot, openTab, teardown, until, ROBOBUS_BIN } from "./harness.mjs";

let studio;
let browser;
let page;
let errors;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
});

after(() => teardown(browser, studio));

test("the shell shows its header, tabs and control", async () => {
  assert.equal(await page.title(), "robobus studio");
  const tabs = page.getByRole("tab");
  assert.deepEqual(await tabs.allTextContents(), [
    "Bus", "Device", "Settings", "Backup", "Commission", "Tune", "Plot", "Waveform", "Program", "Poses", "Robot", "Preview", "Capture",
  ]);
  await page.getByText("you control the devices").waitFor();
  await page.getByRole("button", { name: "Arm", exact: true }).waitFor();
  assert.equal(await page.getByRole("tab", { name: "Bus" }).getAttribute("aria-selected"), "true");
});

test("a wCK scan lists the servos it found", async () => {
  const panel = await openTab(page, "Bus");
  const wck = panel.getByRole("region", { name: "wCK servos (UART)" });
  await wck.getByLabel("Servo IDs").fill("0-5");
  await wck.getByRole("button", { name: "Scan wCK bus" }).click();
  const table = wck.getByRole("table", { name: /wCK servos .* found on sim-wck/ });
  await table.waitFor();
  assert.equal(await table.locator("tbody tr").count(), 6);
  await wck.getByText("Found 6 servos on sim-wck").waitFor();
  const bar = wck.getByRole("progressbar", { name: "wCK scan progress" });
  assert.equal(await bar.getAttribute("value"), "1");
  await screenshot(page, "bus-wck-scan");
});

test("a scan of every bit rate can be stopped", async () => {
  const wck = page.getByRole("region", { name: "wCK servos (UART)" });
  await wck.getByLabel("Servo IDs").fill("0-30");
  await wck.getByLabel("Try every bit rate").check();
  await wck.getByRole("button", { name: "Scan wCK bus" }).click();
  const stop = wck.getByRole("button", { name: "Stop wCK scan" });
  await until(() => stop.isEnabled(), { what: "the Stop button" });
  await page.waitForTimeout(300);
  await stop.click();
  await wck.getByText("stopped", { exact: true }).waitFor({ timeout: 5000 });
  assert.equal(await wck.getByRole("button", { name: "Scan wCK bus" }).isEnabled(), true);
  await wck.getByLabel("Try every bit rate").uncheck();
});

test("Set ID asks first, and Cancel writes nothing", async () => {
  const wck = page.getByRole("region", { name: "wCK servos (UART)" });
  await wck.getByLabel("Servo IDs").fill("0-5");
  await wck.getByRole("button", { name: "Scan wCK bus" }).click();
  await wck.getByText("Found 6 servos on sim-wck").waitFor();
  await wck.getByRole("button", { name: "Set bit rate of servo 2" }).click();
  await wck.getByLabel("New bit rate for servo 2").selectOption("57600");
  await wck.getByRole("button", { name: "Write new bit rate" }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  assert.match(await dialog.textContent(), /EEPROM/);
  await dialog.getByRole("button", { name: "Cancel" }).click();
  await wck.getByText("Cancelled: nothing was written.").waitFor();
});

test("Set ID of a wCK servo, confirmed, moves it to the new ID", async () => {
  const wck = page.getByRole("region", { name: "wCK servos (UART)" });
  await wck.getByRole("button", { name: "Set ID of servo 3" }).click();
  await wck.getByLabel("New ID for servo 3").fill("20");
  await wck.getByRole("button", { name: "Write new ID" }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  assert.match(await dialog.textContent(), /ID/);
  await screenshot(page, "bus-confirm");
  await dialog.getByRole("button", { name: "Confirm" }).click();
  await wck.getByText("Verified: the servo answers at ID 20.").waitFor();
  const sim = await simState(studio.url);
  const ids = sim.wck.map((s) => s.id);
  assert.ok(ids.includes(20), `sim servos: ${ids}`);
  assert.ok(!ids.includes(3), `sim servos: ${ids}`);
  // The table shows it under its new ID.
  await wck.getByRole("button", { name: "Set ID of servo 20" }).waitFor();
});

test("a WHJ scan lists the joints with model and firmware; Set ID is verified", async () => {
  const whj = page.getByRole("region", { name: "WHJ joints (CAN FD)" });
  await whj.getByLabel("Joint IDs").fill("1-7");
  await whj.getByRole("button", { name: "Scan WHJ bus" }).click();
  const table = whj.getByRole("table");
  await table.waitFor();
  assert.equal(await table.locator("tbody tr").count(), 7);
  assert.match(await table.textContent(), /WHJ30/);
  assert.match(await table.textContent(), /D522/);
  await whj.getByRole("button", { name: "Set ID of joint 7" }).click();
  await whj.getByLabel("New ID for joint 7").fill("9");
  await whj.getByRole("button", { name: "Write new ID" }).click();
  await page.getByRole("dialog").getByRole("button", { name: "Confirm" }).click();
  await whj.getByText(/read back 9 \(verified\)/).waitFor();
  await screenshot(page, "bus-whj");
});

test("the serial ports of the machine are listed as robobus ports lists them", async () => {
  const { execFileSync } = await import("node:child_process");
  const want = JSON.parse(execFileSync(ROBOBUS_BIN, ["ports", "--json"], { encoding: "utf8" }));
  const panel = await openTab(page, "Bus");
  const ports = panel.getByRole("region", { name: "Serial ports" });
  await ports.getByRole("button", { name: "List serial ports" }).click();
  const ids = want.results.map((r) => r.id);
  if (ids.length === 0) {
    await ports.getByText(`No serial port found; ${want.summary.where}`).waitFor();
    return;
  }
  const n = ids.length;
  await ports.getByText(`${n} serial port${n === 1 ? "" : "s"} on ${want.summary.os}.`).waitFor();
  const table = ports.getByRole("table", { name: "Serial ports of this machine" });
  assert.deepEqual(await table.locator("thead th").allTextContents(), [
    "Port", "Kind", "USB", "Device", "Adapter", "Use", "Latency timer",
  ]);
  assert.deepEqual(await table.locator("tbody tr td:first-child").allTextContents(), ids);
  assert.deepEqual(
    await table.locator("tbody tr td:nth-child(2)").allTextContents(),
    want.results.map((r) => r.kind),
  );
  await screenshot(page, "bus-ports");
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
