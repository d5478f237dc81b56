// The Capture panel: the session's capture files with their sizes, refreshed on demand,
// and each downloadable as the file `robobus replay` decodes.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { readFile } from "node:fs/promises";
import { execFile } from "node:child_process";
import { promisify } from "node:util";
import { startStudio, launchBrowser, openPage, runRequest, screenshot, openTab, teardown, until, ROBOBUS_BIN } from "./harness.mjs";

let studio;
let browser;
let page;
let errors;
let panel;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  panel = await openTab(page, "Capture");
});

after(() => teardown(browser, studio));

const row = (bus) => panel.locator(`tr[data-bus="${bus}"]`);

test("the capture files of both buses are listed; Refresh shows new traffic", async () => {
  await row("sim-wck").waitFor();
  await row("sim-whj").waitFor();
  assert.match(await row("sim-wck").textContent(), /^sim-wckhex/);
  assert.match(await row("sim-whj").textContent(), /^sim-whjcandump/);
  const size = async (bus) => Number(await row(bus).locator("td.num").getAttribute("title").then((t) => t.split(" ")[0]));
  const wck0 = await size("sim-wck");
  const whj0 = await size("sim-whj");

  await runRequest(studio.url, { op: "wck.status", ids: "0-3" });
  await runRequest(studio.url, { op: "whj.status", joints: "1-2" });
  await panel.getByRole("button", { name: "Refresh" }).click();
  await until(async () => (await size("sim-wck")) > wck0 && (await size("sim-whj")) > whj0, { what: "bigger captures" });
  // The page's history samples every bus all the time: a list fetched after the panel's
  // holds at least what the panel shows.
  const shown = { "sim-wck": await size("sim-wck"), "sim-whj": await size("sim-whj") };
  const list = await (await fetch(new URL("api/capture", studio.url))).json();
  for (const f of list) assert.ok(f.bytes >= shown[f.bus] && shown[f.bus] > 0, `${f.bus}: ${shown[f.bus]} shown, ${f.bytes} listed`);
  await screenshot(page, "capture");
});

for (const [bus, decoded] of [
  ["sim-wck", /status read/i],
  ["sim-whj", /J1 status/],
]) {
  test(`"Download capture of ${bus}" saves the file robobus replay decodes`, async () => {
    const [download] = await Promise.all([
      page.waitForEvent("download"),
      panel.getByRole("link", { name: `Download capture of ${bus}` }).click(),
    ]);
    const file = await download.path();
    const text = await readFile(file, "utf8");
    const served = await (await fetch(new URL(`api/capture/${bus}`, studio.url))).text();
    assert.ok(text.length > 0 && served.startsWith(text.slice(0, 200)), "the download is the served capture");
    assert.match(download.suggestedFilename(), bus === "sim-wck" ? /^sim-wck\.hex\.txt$/ : /^sim-whj\.log$/);
    const { stdout } = await promisify(execFile)(ROBOBUS_BIN, ["replay", file]);
    assert.match(stdout, decoded);
  });
}

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
