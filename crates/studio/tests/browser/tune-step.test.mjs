// The Tune panel's step response: wck.tune run by clicking on the simulated robot, its
// gain sets' traces drawn over each other with the target step; its figures and traces are
// those of the same request through `robobus run`.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startStudio, launchBrowser, openPage, openTab, arm, teardown } from "./harness.mjs";
import { cliRun, docShot, flowOf, recordRequests } from "./cli.mjs";

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

test("the step responses of two gain sets are drawn over the target, their figures as robobus run wck.tune gives them", async () => {
  const panel = await openTab(page, "Tune");
  const section = panel.getByRole("region", { name: "Step response" });
  await section.getByLabel("Step response servo").selectOption("wck|sim-wck|6");
  await section.getByLabel("Gain sets (P,D; P,D)").fill("20,30; 60,10");
  await section.getByLabel("Hold (ms)").fill("300");
  const flow = flowOf(section, "Step response");
  // Not armed: the dry run says it moves; the run is refused, nothing moves.
  await section.getByRole("button", { name: "Dry run: Run the step responses", exact: true }).click();
  await flow.getByText("Dry run of wck.tune: nothing was sent.").waitFor();
  assert.match(await flow.locator('dd[data-field="effect"]').textContent(), /^motion/);
  await arm(page);
  await section.getByRole("button", { name: "Run the step responses", exact: true }).click();
  await flow.getByText("wck.tune ran.", { exact: true }).waitFor({ timeout: 20_000 });
  const request = { op: "wck.tune", id: 6, gains: [[20, 30], [60, 10]], amplitude: 20, hold_ms: 300, torque: 0, keep: "none" };
  const cli = (await cliRun(request)).report;
  const rows = flow.getByRole("table", { name: "Step responses" }).locator("tbody tr");
  assert.equal(await rows.count(), 2);
  for (const [i, r] of cli.results.entries()) {
    const cells = await rows.nth(i).locator("td").allTextContents();
    assert.deepEqual(cells.slice(1, 3), [String(r.p), String(r.d)]);
    assert.equal(Number(cells[4]), Number(r.overshoot_pct.toFixed(3)));
    assert.equal(Number(cells[6]), Number(r.steady_state_error.toFixed(3)));
  }
  // One trace per gain set and the target, each trace's points the report's readings.
  const chart = flow.getByRole("img", { name: /Step responses: 2 gain sets/ });
  const series = await chart.locator("polyline").evaluateAll((ls) => ls.map((l) => [l.dataset.series, l.getAttribute("points").trim().split(/\s+/)]));
  assert.deepEqual(series.map((s) => s[0]), ["target", "set 1", "set 2"]);
  // The target: the start, the step at 0 ms, the target to the end.
  const target = series[0][1].map((p) => p.split(",").map(Number));
  assert.equal(target.length, 4);
  assert.equal(target[1][0], target[2][0]);
  // Each trace starts at the start and, the servo settled without error (robobus run's
  // steady-state error is 0), ends on the target.
  for (const [i, r] of cli.results.entries()) {
    assert.equal(r.steady_state_error, 0);
    const points = series[i + 1][1].map((p) => p.split(",").map(Number));
    assert.equal(points[0][1], target[0][1]);
    assert.equal(points.at(-1)[1], target[3][1]);
  }
  assert.match(await flow.locator('p[data-field="best"]').textContent(), new RegExp(`^Step from ${cli.summary.start} to ${cli.summary.target} `));
  await docShot(section, "tune-step");
});

test("the WHJ register table reads every setting of a joint with one whj.backup, the values robobus run reads", async () => {
  const panel = await openTab(page, "Tune");
  const whj = panel.getByRole("region", { name: "WHJ joint registers" });
  await whj.getByRole("table", { name: "WHJ registers" }).waitFor();
  await whj.getByLabel("Joint", { exact: true }).selectOption("whj|sim-whj|5");
  sent.clear();
  await whj.getByRole("button", { name: "Read every setting", exact: true }).click();
  const cli = (await cliRun({ op: "whj.backup", joint: 5 })).report.summary.settings;
  await whj.getByText(`Joint 5: ${cli.length} settings read with one whj.backup.`).waitFor();
  assert.deepEqual(sent.runs.map((r) => r.op), ["whj.backup"]);
  const table = whj.getByRole("table", { name: "WHJ registers" });
  for (const s of cli) {
    const name = (await table.getByRole("button", { name: `Select ${s.register}`, exact: true }).count()) ? s.register : `${s.register}_L`;
    const row = table.locator("tr", { has: page.getByRole("button", { name: `Select ${name}`, exact: true }) });
    assert.match(await row.locator("td").nth(6).textContent(), new RegExp(`raw ${s.raw}\\)?$`), name);
  }
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
