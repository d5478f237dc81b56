// The Commission panel: wCK wheel mode and I/O, WHJ bit rates, limits and gains, the end
// board; each done by clicking on the simulated robot and checked against the same request
// through `robobus run` and reads of the devices.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startStudio, launchBrowser, openPage, runRequest, openTab, arm, teardown } from "./harness.mjs";
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
  panel = await openTab(page, "Commission");
});

after(() => teardown(browser, studio));

test("the wCK outputs written at runtime read back as wck.get io, and robobus run's same write reports the same", async () => {
  const card = panel.getByRole("region", { name: "wCK I/O" });
  await card.getByLabel("I/O servo").selectOption("wck|sim-wck|1");
  await card.getByLabel("DO1 on").check();
  await card.getByLabel("DO2 on").check();
  await card.getByRole("button", { name: "Write the outputs", exact: true }).click();
  const flow = flowOf(card, "I/O");
  await flow.getByText("wck.set ran.").waitFor();
  assert.equal(await page.getByRole("dialog").count(), 0);
  const request = { op: "wck.set", param: "io", id: 1, outputs: 3, runtime: true };
  const cli = (await cliRun(request)).report.results[0];
  const cells = await flow.getByRole("table", { name: "I/O" }).locator("tbody tr td").allTextContents();
  assert.deepEqual(cells.slice(0, 4), [String(cli.id), String(cli.outputs), String(cli.do1), String(cli.do2)]);
  const get = await runRequest(studio.url, { op: "wck.get", param: "io", id: 1 });
  assert.deepEqual([get.results[0].do1, get.results[0].do2], [true, true]);
});

test("wheel mode turns the servo for its time and stops it in its safe state, as robobus run's wheel run does", async () => {
  const card = panel.getByRole("region", { name: "wCK wheel mode" });
  await card.getByLabel("Wheel servo").selectOption("wck|sim-wck|0");
  await card.getByLabel("Speed (0..15)").fill("5");
  await card.getByLabel("Duration (s)").fill("0.5");
  await arm(page);
  await card.getByRole("button", { name: "Turn the wheel", exact: true }).click();
  const flow = flowOf(card, "Wheel");
  await flow.getByText("wck.wheel ran.").waitFor({ timeout: 10_000 });
  const cli = (await cliRun({ op: "wck.wheel", id: 0, direction: "ccw", speed: 5, duration: 0.5 })).report.results[0];
  const cells = await flow.getByRole("table", { name: "Wheel run" }).locator("tbody tr td").allTextContents();
  assert.equal(cells[0], "0");
  assert.equal(cells[3], cli.stopped);
  assert.ok(Number(cells[2]) >= 500, `ran ${cells[2]} ms`);
});

test("a WHJ limit is read and written in its unit, as whj.read reads it and robobus run's write reports", async () => {
  const card = panel.getByRole("region", { name: "WHJ limits and gains" });
  await card.getByLabel("Limits joint").selectOption("whj|sim-whj|3");
  await card.getByLabel("Limit or gain", { exact: true }).selectOption("LIT_MAX_POSITION");
  await card.getByText(/safety class: plain/).waitFor();
  await card.getByLabel("Limit or gain value").fill("300");
  await card.getByRole("button", { name: "Write the limit or gain", exact: true }).click();
  const flow = flowOf(card, "Limits and gains");
  await flow.getByText("whj.write ran.").waitFor();
  const cli = (await cliRun({ op: "whj.write", joints: "3", register: "LIT_MAX_POSITION", value: 300 })).report.results[0];
  const cells = await flow.getByRole("table", { name: "Register" }).locator("tbody tr td").allTextContents();
  assert.deepEqual(cells, [String(cli.id), cli.register, cli.addr, String(cli.raw), String(cli.value), cli.unit]);
  const read = await runRequest(studio.url, { op: "whj.read", joints: "3", register: "LIT_MAX_POSITION" });
  assert.equal(read.results[0].raw, 3000000);
});

test("new bit rates ask first (register class) and an enabled joint is refused, nothing written, as robobus run refuses it", async () => {
  const card = panel.getByRole("region", { name: "WHJ bit rates" });
  await card.getByLabel("Bit rate joint").selectOption("whj|sim-whj|4");
  await card.getByLabel("Arbitration bit rate").selectOption("500000");
  await card.getByLabel("Data bit rate").selectOption("2000000");
  await card.getByRole("button", { name: "Write the bit rates", exact: true }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  assert.match(await dialog.textContent(), /bit rates/);
  await dialog.getByRole("button", { name: "Confirm", exact: true }).click();
  const flow = flowOf(card, "Bit rates");
  const cli = (await cliRun({ op: "whj.set-rates", joints: "4", bitrate: 500000, dbitrate: 2000000, confirm: true })).report;
  await flow.getByText(`whj.set-rates ran; ${cli.results[0].kind}: ${cli.results[0].error}`).waitFor();
  const read = await runRequest(studio.url, { op: "whj.read", joints: "4", register: "SYS_BPS_CANFD_BRT" });
  assert.equal(read.results[0].raw, (await cliRun({ op: "whj.read", joints: "4", register: "SYS_BPS_CANFD_BRT" })).report.results[0].raw);
});

test("the end board's state is asked for; the simulated arm has none, and the page says what robobus run says", async () => {
  const card = panel.getByRole("region", { name: "WHJ end board" });
  await card.getByLabel("End board action").selectOption("status");
  await card.getByRole("button", { name: "Run the end-board action", exact: true }).click();
  const flow = flowOf(card, "End board");
  const cli = (await cliRun({ op: "whj.end-board", action: "status" })).report;
  // The board's row fails as robobus run's does: its kind and its message (the time waited
  // is the studio's reply timeout, on the wall clock, not the CLI's on its virtual clock).
  assert.equal(cli.failed, "no-device");
  const message = cli.results[0].error.replace(/[.*+?^${}()|[\]\\]/g, "\\$&").replace(/\d+ ms/, "\\d+ ms");
  await flow.getByText(new RegExp(`^whj\\.end-board ran; ${cli.results[0].kind}: ${message}$`)).waitFor();
  await docShot(panel, "commission");
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
