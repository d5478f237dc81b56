// The browser tests' harness: a `robobus studio` server on the simulated robot, headless
// Chromium through playwright-core, and helpers to read the simulators' own state.
// Run through scripts/studio/test-browser, which installs both and sets ROBOBUS_BIN.

import { spawn } from "node:child_process";
import { createRequire } from "node:module";
import { mkdirSync } from "node:fs";
import path from "node:path";
import { fileURLToPath } from "node:url";

const here = path.dirname(fileURLToPath(import.meta.url));
const root = path.resolve(here, "../../../..");
const modules = path.resolve(process.env.STUDIO_NODE_MODULES ?? path.join(root, "target/studio-node/node_modules"));
const require = createRequire(path.join(modules, "noop.js"));
const { chromium } = require("playwright-core");

export const ROBOBUS_BIN = process.env.ROBOBUS_BIN ?? path.join(root, "target/debug/robobus");
export const SCREENS = process.env.STUDIO_SCREENS ?? path.join(root, "target/studio-screens");

/**
 * The heartbeat timeout the tests' studios use unless a test gives its own
 * `--heartbeat-timeout-ms`: the studio's default (1000 ms) unless
 * STUDIO_HEARTBEAT_TIMEOUT_MS says otherwise.
 */
export const HEARTBEAT_TIMEOUT_MS = process.env.STUDIO_HEARTBEAT_TIMEOUT_MS;

/**
 * Start `robobus studio --port 0 ...args`; resolves when its first stdout line names the
 * address: {url, proc, stop()}. `url` ends with `/`.
 */
export function startStudio(args = []) {
  return new Promise((resolve, reject) => {
    const extra =
      args.includes("--heartbeat-timeout-ms") || !HEARTBEAT_TIMEOUT_MS ? [] : ["--heartbeat-timeout-ms", HEARTBEAT_TIMEOUT_MS];
    const proc = spawn(ROBOBUS_BIN, ["studio", "--port", "0", ...extra, ...args], {
      stdio: ["ignore", "pipe", "pipe"],
    });
    let out = "";
    let err = "";
    let done = false;
    const timer = setTimeout(() => fail(new Error(`studio did not print its address within 60 s\nstdout: ${out}\nstderr: ${err}`)), 60_000);
    const fail = (e) => {
      if (done) return;
      done = true;
      clearTimeout(timer);
      proc.kill("SIGKILL");
      reject(e);
    };
    proc.stderr.on("data", (d) => {
      err += d;
      if (err.length > 20_000) err = err.slice(-10_000);
    });
    proc.stdout.on("data", (d) => {
      out += d;
      const m = /studio: (http:\/\/[^\s]+\/)/.exec(out);
      if (m && !done) {
        done = true;
        clearTimeout(timer);
        const stop = () =>
          new Promise((res) => {
            if (proc.exitCode !== null || proc.signalCode !== null) return res();
            proc.once("exit", () => res());
            proc.kill("SIGTERM");
            setTimeout(() => proc.kill("SIGKILL"), 3000).unref();
          });
        resolve({ url: m[1], proc, stop, stderr: () => err });
      }
    });
    proc.on("error", fail);
    proc.on("exit", (code, signal) => fail(new Error(`studio exited (${code ?? signal}) before printing its address\nstderr: ${err}`)));
  });
}

/** Headless Chromium (the system's /usr/bin/chromium). */
export function launchBrowser() {
  return chromium.launch({
    executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
    headless: true,
    args: [
      "--no-sandbox",
      "--disable-gpu",
      "--no-first-run",
      "--disable-background-networking",
      "--disable-component-update",
      "--disable-sync",
      "--disable-quic",
    ],
  });
}

/**
 * A new page (its own context, 1280×900) at `url`, waiting until the studio is connected.
 * Console errors and page errors are collected in `errors`.
 */
export async function openPage(browser, url, { viewport = { width: 1280, height: 900 }, wait = true } = {}) {
  const context = await browser.newContext({ viewport, acceptDownloads: true });
  const page = await context.newPage();
  const errors = [];
  page.on("console", (msg) => {
    if (msg.type() === "error") errors.push(`console: ${msg.text()}`);
  });
  page.on("pageerror", (e) => errors.push(`page: ${e.message}`));
  await page.goto(url);
  if (wait) await page.waitForFunction(() => window.studio?.state?.connected === true, null, { timeout: 15_000 });
  return { page, errors, context };
}

/** The simulators' own state: GET /api/sim. */
export async function simState(url) {
  const res = await fetch(new URL("api/sim", url));
  if (!res.ok) throw new Error(`GET /api/sim: ${res.status} ${await res.text()}`);
  return res.json();
}

/** One simulated WHJ joint's or wCK servo's state. */
export async function simJoint(url, id) {
  return (await simState(url)).whj.find((j) => j.id === id);
}
export async function simServo(url, id) {
  return (await simState(url)).wck.find((s) => s.id === id);
}

/** Run a request as a script would (POST /api/run, no session). */
export async function runRequest(url, request) {
  const res = await fetch(new URL("api/run", url), {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify(request),
  });
  const body = await res.json();
  if (!res.ok) throw new Error(`POST /api/run ${JSON.stringify(request)}: ${res.status} ${JSON.stringify(body)}`);
  return body;
}

/** Poll `fn` until it returns a truthy value (returned) or `timeout` ms pass (throws with the last value). */
export async function until(fn, { timeout = 5000, interval = 100, what = "condition" } = {}) {
  const end = Date.now() + timeout;
  let last;
  for (;;) {
    last = await fn();
    if (last) return last;
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}; last: ${JSON.stringify(last)}`);
    await new Promise((r) => setTimeout(r, interval));
  }
}

/** Save a full-page screenshot as target/studio-screens/NAME.png. */
export async function screenshot(page, name) {
  mkdirSync(SCREENS, { recursive: true });
  const file = path.join(SCREENS, `${name}.png`);
  await page.screenshot({ path: file, fullPage: true });
  return file;
}

/** Click the tab of a panel and wait for its panel to show. */
export async function openTab(page, name) {
  await page.getByRole("tab", { name, exact: true }).click();
  const panel = page.getByRole("tabpanel", { name, exact: true });
  await panel.waitFor({ state: "visible" });
  return panel;
}

/** Arm from the header and wait until the page says so. */
export async function arm(page) {
  await page.getByRole("button", { name: "Arm", exact: true }).click();
  await page.waitForFunction(() => window.studio.state.armed === true, null, { timeout: 5000 });
}

/** The usual ending of a test file: close the browser and stop the server. */
export async function teardown(browser, studio) {
  await browser?.close().catch(() => {});
  await studio?.stop();
}
