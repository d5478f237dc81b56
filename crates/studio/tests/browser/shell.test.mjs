// The shell and core: one controller among several pages, the heartbeat's safe state,
// a read-only studio, and a studio behind a token.

import { test, after } from "node:test";
import assert from "node:assert/strict";
import { writeFileSync, mkdtempSync } from "node:fs";
import { tmpdir } from "node:os";
import path from "node:path";
import { startStudio, launchBrowser, openPage, screenshot, openTab, arm, until } from "./harness.mjs";

let browser;
const servers = [];

after(async () => {
  await browser?.close().catch(() => {});
  for (const s of servers) await s.stop();
});

async function studio(args = []) {
  const s = await startStudio(args);
  servers.push(s);
  browser ??= await launchBrowser();
  return s;
}

test("a second page watches; it takes control once the first releases it", async () => {
  const s = await studio();
  const a = await openPage(browser, s.url);
  await a.page.getByText("you control the devices").waitFor();
  const b = await openPage(browser, s.url);
  await b.page.getByText("another page controls: watching").waitFor();
  assert.equal(await b.page.getByRole("button", { name: "Arm", exact: true }).isVisible(), false);
  const take = b.page.getByRole("button", { name: "Take control" });
  await take.waitFor();
  // The watcher's jog stays disabled.
  const panel = await openTab(b.page, "Device");
  await panel.getByText("Arm to jog.").waitFor();
  await screenshot(b.page, "shell-watching");
  await a.page.getByRole("button", { name: "Release control" }).click();
  await a.page.getByText("watching (nobody controls)").waitFor();
  await take.click();
  await b.page.getByText("you control the devices").waitFor();
  await b.page.getByRole("button", { name: "Arm", exact: true }).waitFor();
  assert.deepEqual(a.errors, []);
  assert.deepEqual(b.errors, []);
  await a.context.close();
  await b.context.close();
});

test("a lost heartbeat brings the devices to the safe state and the page says why", async () => {
  const s = await studio();
  const { page, errors, context } = await openPage(browser, s.url);
  await arm(page);
  // Move a joint so that the safe state has a device to hold.
  await page.evaluate(() => window.studio.jog("whj", "sim-whj", 1, 1));
  // Stop the link's heartbeat while the page stays alive, as a network that loses it would
  // (a frozen page: arming.test.mjs).
  await page.evaluate(() => window.studio.ws.beat(false));
  const banner = page.getByRole("alert").filter({ hasText: "Devices brought to the safe state" });
  await banner.waitFor({ timeout: 3000 });
  assert.match(await banner.textContent(), /heartbeat/);
  const reason = page.locator("header").getByRole("alert");
  assert.match(await reason.textContent(), /heartbeat lost\. The heartbeat did not reach the server in time/);
  await until(() => page.evaluate(() => window.studio.state.armed === false), { what: "disarmed" });
  await page.getByText("disarmed", { exact: true }).waitFor();
  await screenshot(page, "shell-safe");
  await banner.getByRole("button", { name: "Dismiss" }).click();
  await banner.waitFor({ state: "hidden" });
  assert.deepEqual(errors, []);
  await context.close();
});

test("after the WebSocket drops, the page reconnects, takes control again and its streams resume", async () => {
  const s = await studio();
  const { page, errors, context } = await openPage(browser, s.url);
  const panel = await openTab(page, "Device");
  await panel.getByLabel("Device", { exact: true }).selectOption({ label: "Joint 2 · j2" });
  await panel.getByText("live · 20 Hz").waitFor();
  await page.evaluate(() => {
    window.linkBefore = window.studio.ws;
    window.studio.ws.close();
  });
  await until(() => page.evaluate(() => window.studio.state.connected && window.studio.ws !== window.linkBefore), {
    what: "a new connection",
  });
  await page.getByText("you control the devices").waitFor();
  // Samples flow again on the new connection.
  const seen = await page.evaluate(
    () =>
      new Promise((resolve) => {
        // The Device panel's own streams (the page's history streams run too).
        const off = window.studio.on("telemetry", (m) => {
          if (!m.stream.startsWith("device.")) return;
          off();
          resolve(m.stream);
        });
      }),
  );
  assert.match(seen, /^device\./);
  assert.deepEqual(errors, []);
  await context.close();
});

test("a read-only studio shows read-only, offers no Arm and no writes", async () => {
  const s = await studio(["--read-only"]);
  const { page, errors, context } = await openPage(browser, s.url);
  await page.getByText("read-only", { exact: true }).waitFor();
  assert.equal(await page.getByRole("button", { name: "Arm", exact: true }).count(), 0);
  assert.equal(await page.getByRole("button", { name: "Take control" }).isVisible(), false);
  const panel = await openTab(page, "Device");
  await panel.getByText("Read-only studio: no jogging.").waitFor();
  await panel.getByLabel("Device", { exact: true }).selectOption({ label: "Joint 1 · j1" });
  await panel.getByText("live · 20 Hz").waitFor();
  assert.equal(await panel.getByRole("button", { name: "Disable joint 1", exact: true }).isDisabled(), true);
  // Reading still works; writing is not offered.
  const tune = await openTab(page, "Tune");
  await tune.getByText(/Read servo \d+ at/).waitFor();
  assert.equal(await tune.getByRole("button", { name: "Write Position gains to EEPROM" }).isDisabled(), true);
  await screenshot(page, "shell-read-only");
  assert.deepEqual(errors, []);
  await context.close();
});

test("a studio behind a token: the page reads it from its URL", async () => {
  const dir = mkdtempSync(path.join(tmpdir(), "studio-token-"));
  const file = path.join(dir, "token");
  writeFileSync(file, "test-token-0123456789abcdef\n");
  const s = await studio(["--listen", "127.0.0.1:0", "--token-file", file]);
  const bare = await openPage(browser, s.url, { wait: false });
  await bare.page.getByRole("alert").getByText("Could not connect").waitFor();
  await bare.context.close();
  const { page, context } = await openPage(browser, `${s.url}#token=test-token-0123456789abcdef`);
  await page.getByText("you control the devices").waitFor();
  const report = await page.evaluate(() => window.studio.run({ op: "whj.status", joints: "1" }));
  assert.equal(report.results[0].id, 1);
  await context.close();
});
