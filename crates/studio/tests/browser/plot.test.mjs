// The Plot panel: live charts of a joint, its target after a move, pause and zoom, and the
// CSV and PNG exports.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { readFile } from "node:fs/promises";
import { startStudio, launchBrowser, openPage, screenshot, openTab, arm, teardown, until } from "./harness.mjs";

let studio;
let browser;
let page;
let errors;
let panel;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  panel = await openTab(page, "Plot");
});

after(() => teardown(browser, studio));

test("the charts show one joint, one chart per unit", async () => {
  assert.equal(await panel.getByRole("checkbox", { name: "Joint 1 · j1" }).isChecked(), true);
  for (const name of ["Position (deg) chart", "Speed (rpm) chart", "Current (mA) chart"]) {
    await panel.getByRole("figure", { name }).locator("canvas").waitFor();
  }
  const legend = await panel.getByRole("figure", { name: "Position (deg) chart" }).textContent();
  assert.match(legend, /joint 1 actual/);
  assert.match(legend, /joint 1 target/);
  await panel.getByLabel("Window").selectOption("10");
});

test("a move shows its target; the CSV export holds target and actual", async () => {
  await arm(page);
  await page.evaluate(() => window.studio.run({ op: "whj.move", joint: 1, degrees: 12, max_speed: 60 }));
  await page.waitForTimeout(1500);
  await screenshot(page, "plot-move");
  const [download] = await Promise.all([
    page.waitForEvent("download"),
    panel.getByRole("button", { name: "Export CSV" }).click(),
  ]);
  const csv = await readFile(await download.path(), "utf8");
  const [header, ...rows] = csv.trim().split("\n");
  const cols = header.split(",");
  assert.deepEqual(cols.slice(0, 5), [
    "unix_ms",
    "joint 1 position actual (deg)",
    "joint 1 position target (deg)",
    "joint 1 speed (rpm)",
    "joint 1 current (mA)",
  ]);
  assert.ok(rows.length > 20, `${rows.length} rows`);
  const last = rows.map((r) => r.split(",")).filter((r) => r[1] !== "");
  const actual = Number(last[last.length - 1][1]);
  assert.ok(Math.abs(actual - 12) < 0.5, `last position ${actual}`);
  const targets = rows.map((r) => r.split(",")[2]).filter((v) => v !== "").map(Number);
  assert.ok(targets.length > 0, "some target values");
  assert.ok(Math.abs(targets[targets.length - 1] - 12) < 0.01, `last target ${targets[targets.length - 1]}`);
});

test("Pause and Resume; a drag zooms and pauses, Reset zoom resumes", async () => {
  const pause = panel.getByRole("button", { name: "Pause" });
  await pause.click();
  await panel.getByRole("button", { name: "Resume" }).click();
  await panel.getByRole("button", { name: "Pause" }).waitFor();
  const over = panel.getByRole("figure", { name: "Position (deg) chart" }).locator(".u-over");
  const box = await over.boundingBox();
  await page.mouse.move(box.x + box.width * 0.3, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width * 0.6, box.y + box.height / 2, { steps: 5 });
  await page.mouse.up();
  await panel.getByRole("button", { name: "Resume" }).waitFor();
  const range = await page.evaluate(() => {
    const u = document.querySelector("#panel-plot .uplot");
    return u ? u.getBoundingClientRect().width : 0;
  });
  assert.ok(range > 0);
  await panel.getByRole("button", { name: "Reset zoom" }).click();
  await panel.getByRole("button", { name: "Pause" }).waitFor();
});

test("Export PNG makes a PNG file", async () => {
  const [download] = await Promise.all([
    page.waitForEvent("download"),
    panel.getByRole("button", { name: "Export PNG" }).click(),
  ]);
  const png = await readFile(await download.path());
  assert.deepEqual([...png.subarray(1, 4)], [0x50, 0x4e, 0x47]);
  assert.ok(png.length > 5000, `${png.length} bytes`);
  await screenshot(page, "plot");
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
