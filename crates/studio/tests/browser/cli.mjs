// The commissioning panels' tests' helpers: the same request through `robobus run` (the
// CLI, on its own fresh built-in simulated robot), the page's requests as the server got
// them, and the docs' screenshots.

import { spawn } from "node:child_process";
import path from "node:path";
import { fileURLToPath } from "node:url";
import { mkdirSync } from "node:fs";
import { ROBOBUS_BIN, SCREENS } from "./harness.mjs";

const here = path.dirname(fileURLToPath(import.meta.url));
export const DOCS = path.resolve(here, "../../../../docs");

/** Run requests (one or an array) through `robobus run --json -`: the reports as JSON. */
export function cliRun(request) {
  return new Promise((resolve, reject) => {
    const proc = spawn(ROBOBUS_BIN, ["run", "--json", "-"], { stdio: ["pipe", "pipe", "pipe"] });
    let out = "";
    let err = "";
    const timer = setTimeout(() => {
      proc.kill("SIGKILL");
      reject(new Error(`robobus run timed out: ${JSON.stringify(request)}`));
    }, 60_000);
    proc.stdout.on("data", (d) => (out += d));
    proc.stderr.on("data", (d) => (err += d));
    proc.on("error", reject);
    proc.on("exit", (code) => {
      clearTimeout(timer);
      // A failed request prints its report, then its error document.
      const first = out.trim().split(/\n(?=[{[])/)[0];
      try {
        resolve({ code, report: JSON.parse(first) });
      } catch (e) {
        reject(new Error(`robobus run ${JSON.stringify(request)}: exit ${code}, ${e.message}\nstdout: ${out}\nstderr: ${err}`));
      }
    });
    proc.stdin.end(JSON.stringify(request));
  });
}

/** Every request the page sent to POST /api/run and /api/plan, and over the WebSocket (`run`). */
export function recordRequests(page) {
  const runs = [];
  const plans = [];
  page.on("request", (r) => {
    if (r.method() !== "POST") return;
    const u = new URL(r.url());
    if (u.pathname === "/api/run") runs.push(JSON.parse(r.postData() ?? "null"));
    if (u.pathname === "/api/plan") plans.push(JSON.parse(r.postData() ?? "null"));
  });
  page.on("websocket", (ws) => {
    ws.on("framesent", (f) => {
      try {
        const m = JSON.parse(f.payload);
        if (m.type === "run") runs.push(m.request);
      } catch {
        /* not JSON */
      }
    });
  });
  return { runs, plans, clear: () => ((runs.length = 0), (plans.length = 0)) };
}

/**
 * A screenshot of one element for docs/studio.md, studio-NAME.png: into the tests' screens
 * folder, and into docs/ itself when STUDIO_DOC_SHOTS=1 (a test run does not rewrite the
 * docs' pictures unasked). Taken from the whole page at its top (clipped to the element),
 * so the header that stays on screen does not cover the element's top as it would in a
 * scrolled window.
 */
export async function docShot(locator, name) {
  const dir = process.env.STUDIO_DOC_SHOTS === "1" ? DOCS : SCREENS;
  mkdirSync(dir, { recursive: true });
  const file = path.join(dir, `studio-${name}.png`);
  const page = locator.page();
  await page.evaluate(() => window.scrollTo(0, 0));
  const box = await locator.boundingBox();
  await page.screenshot({ path: file, fullPage: true, clip: box });
  return file;
}

/** The flow group of a panel's form (its dry run, status and report). */
export function flowOf(scope, name) {
  return scope.getByRole("group", { name: `${name} flow` });
}
