// The Program panel: Check points at a bad token (line, column, caret there) and shows a
// good program's instructions and upload packet; Upload (confirmed) stores it, which
// changes what Download returns and what the simulated servo does; Verify compares.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startStudio, launchBrowser, openPage, simServo, runRequest, screenshot, openTab, arm, teardown, until } from "./harness.mjs";

let studio;
let browser;
let page;
let errors;
let panel;

const PROGRAM = "# to 60 and stay\nmove 60 torque 0\ndelay 100ms\nend\n";

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  await page.waitForFunction(() => window.studio.state.controller === true);
  panel = await openTab(page, "Program");
  await panel.getByLabel("Servo", { exact: true }).selectOption({ label: "Servo 3 · s3" });
});

after(() => teardown(browser, studio));

const status = () => panel.getByRole("status").textContent();

test("Check shows a bad token at its line and column and moves the caret there", async () => {
  const editor = panel.getByLabel("Motion program");
  await editor.fill("move 60 torque 0\ndelay 100ms\nmove 300 torque 1\nend\n");
  await panel.getByRole("button", { name: "Check", exact: true }).click();
  await until(async () => /line 3, column 6/.test(await status()), { what: "the error position" });
  assert.match(await status(), /position 300 is out of range/);
  const sel = await editor.evaluate((t) => [t.selectionStart, t.selectionEnd, document.activeElement === t]);
  const at = "move 60 torque 0\ndelay 100ms\nmove ".length;
  assert.deepEqual(sel, [at, at + 3, true]);
});

test("Check shows a good program's instructions and its upload packet", async () => {
  await panel.getByLabel("Motion program").fill(PROGRAM);
  await panel.getByRole("button", { name: "Check", exact: true }).click();
  await until(async () => /OK: 3 instructions/.test(await status()), { what: "the check" });
  const table = panel.getByRole("table", { name: "3 instructions (at most 8)" });
  assert.equal(await table.locator("tbody tr").count(), 3);
  assert.match(await table.textContent(), /move 60 torque 0/);
  // The packet for servo 3, as `robobus wck program check --id 3` prints it.
  const check = await runRequest(studio.url, { op: "wck.program.check", program: PROGRAM, id: 3 });
  assert.equal(await panel.getByLabel("Upload packet").textContent(), check.summary.upload_packet.hex);
  await screenshot(page, "program-check");
});

test("Upload asks first, then Download and Verify see the new program; the servo runs it", async () => {
  await panel.getByRole("button", { name: "Download", exact: true }).click();
  await until(async () => /holds a program of 0 instructions/.test(await status()), { what: "the empty program" });
  // An uploaded program starts at once (the servo moves): disarmed, the page offers no upload.
  assert.equal(await panel.getByRole("button", { name: "Upload", exact: true }).isDisabled(), true);
  await panel.getByText("Arm to upload: the servo starts the program at once.").waitFor();
  await arm(page);

  await panel.getByRole("button", { name: "Upload", exact: true }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  assert.match(await dialog.textContent(), /non-volatile|EEPROM/);
  await dialog.getByRole("button", { name: "Confirm" }).click();
  await until(async () => /Uploaded: servo 3 holds 3 instructions/.test(await status()), { what: "the upload" });
  // The servo runs its stored program by itself: it goes to 60.
  await until(async () => Math.abs((await simServo(studio.url, 3)).position - 60) <= 2, {
    timeout: 5000,
    what: "servo 3 at 60",
  });

  await panel.getByRole("button", { name: "Download", exact: true }).click();
  await until(async () => /Servo 3 holds a program of 3 instructions/.test(await status()), { what: "the download" });
  await panel.getByRole("button", { name: "Verify", exact: true }).click();
  await until(async () => /^Equal: servo 3 holds 3 instructions, the editor has 3/.test(await status()), { what: "equal" });
  await screenshot(page, "program");

  await panel.getByLabel("Motion program").fill(`${PROGRAM}none\n`);
  await panel.getByRole("button", { name: "Verify", exact: true }).click();
  await until(async () => /^Different: servo 3 holds 3 instructions, the editor has 4/.test(await status()), { what: "different" });
});

test("a cancelled upload sends nothing", async () => {
  await panel.getByLabel("Motion program").fill("end\n");
  await panel.getByRole("button", { name: "Upload", exact: true }).click();
  await page.getByRole("dialog").getByRole("button", { name: "Cancel" }).click();
  await until(async () => /Upload cancelled/.test(await status()), { what: "the cancel" });
  const down = await runRequest(studio.url, { op: "wck.program.download", id: 3 });
  assert.equal(down.results[0].instructions, 3);
});

test("no console errors but the one expected 400 (the bad program's check)", () => {
  // Chromium logs every non-2xx answer of fetch() as a console error.
  const bad = errors.filter((e) => /status of 400 \(Bad Request\)/.test(e));
  assert.equal(bad.length, 1, errors.join("\n"));
  assert.deepEqual(errors.filter((e) => !bad.includes(e)), []);
});
