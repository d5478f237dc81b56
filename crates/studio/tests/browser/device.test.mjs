// The Device panel: live readouts, jogging a WHJ joint after Arm, the wCK and WHJ
// commands, and the safe state on Disarm; each checked against the simulators.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import {
  startStudio, launchBrowser, openPage, simJoint, simServo, screenshot, openTab, arm, teardown, until,
} from "./harness.mjs";

let studio;
let browser;
let page;
let errors;
let panel;

before(async () => {
  studio = await startStudio();
  browser = await launchBrowser();
  ({ page, errors } = await openPage(browser, studio.url));
  panel = await openTab(page, "Device");
});

after(() => teardown(browser, studio));

const number = async (locator) => Number.parseFloat(await locator.textContent());

test("a WHJ joint's readouts are live and carry their units", async () => {
  await panel.getByLabel("Device", { exact: true }).selectOption({ label: "Joint 1 · j1" });
  const pos = panel.getByLabel("Position (deg)");
  await until(async () => !Number.isNaN(await number(pos)), { what: "a position reading" });
  await until(async () => (await panel.getByLabel("Voltage (V)").textContent()) === "24.00", { what: "the voltage" });
  assert.equal(await panel.getByLabel("Temperature (°C)").textContent(), "25.0");
  assert.equal(await panel.getByLabel("Mode", { exact: true }).textContent(), "position");
  await panel.getByText("live · 20 Hz").waitFor();
});

test("jogging is disabled until armed, then moves the joint toward the slider", async () => {
  const slider = panel.getByLabel("Jog target joint 1 (deg)");
  assert.equal(await slider.isDisabled(), true);
  await panel.getByText("Arm to jog.").waitFor();
  await arm(page);
  await until(() => slider.isEnabled(), { what: "the slider to enable" });
  await slider.fill("10");
  const j = await until(
    async () => {
      const s = await simJoint(studio.url, 1);
      return s.target_position_deg > 9.9 && s.position_deg > 5 ? s : null;
    },
    { timeout: 8000, what: "sim joint 1 to move toward 10°" },
  );
  assert.ok(j.target_position_deg <= 10.0001, JSON.stringify(j));
  await until(async () => (await number(panel.getByLabel("Position (deg)"))) > 5, { what: "the readout to follow" });
  await screenshot(page, "device-whj-jog");
});

test("Jog + steps the joint up by the chosen step", async () => {
  const before = (await until(async () => {
    const s = await simJoint(studio.url, 1);
    return Math.abs(s.position_deg - s.target_position_deg) < 0.05 ? s : null;
  }, { timeout: 8000, what: "joint 1 to settle" })).target_position_deg;
  await panel.getByLabel("Jog step").selectOption("2");
  await panel.getByRole("button", { name: /^Jog \+/ }).click();
  await until(async () => (await simJoint(studio.url, 1)).target_position_deg > before + 1.9, {
    what: "the target to rise by 2°",
  });
  const after = (await simJoint(studio.url, 1)).target_position_deg;
  assert.ok(after < before + 2.1, `from ${before} to ${after}`);
});

test("WHJ commands: Disable, Enable, Set mode; Save asks first", async () => {
  await panel.getByRole("button", { name: "Disable joint 1", exact: true }).click();
  await until(async () => (await simJoint(studio.url, 1)).enabled === false, { what: "joint 1 disabled" });
  await panel.getByRole("button", { name: "Save to flash joint 1", exact: true }).click();
  const dialog = page.getByRole("dialog");
  await dialog.waitFor();
  await dialog.getByRole("button", { name: "Cancel", exact: true }).click();
  await dialog.waitFor({ state: "detached" });
  await panel.getByRole("button", { name: "Enable joint 1", exact: true }).click();
  await until(async () => (await simJoint(studio.url, 1)).enabled === true, { what: "joint 1 enabled" });
  await panel.getByLabel("New mode").selectOption("speed");
  await panel.getByRole("button", { name: "Set mode of joint 1", exact: true }).click();
  await until(async () => (await simJoint(studio.url, 1)).mode === 2, { what: "speed mode" });
  await panel.getByLabel("New mode").selectOption("position");
  await panel.getByRole("button", { name: "Set mode of joint 1", exact: true }).click();
  await until(async () => (await simJoint(studio.url, 1)).mode === 3, { what: "position mode" });
});

test("a picked mode is what Set mode sends, though the joint's status keeps coming", async () => {
  const list = panel.getByLabel("New mode");
  await until(async () => (await list.inputValue()) === "position", { what: "the list at the joint's mode" });
  await list.selectOption("speed");
  // The focus leaves the list, as a click on Set mode takes it, while the status streams in
  // at 2 Hz with the joint still in position mode: the pick stays.
  await list.evaluate((e) => e.blur());
  await page.waitForTimeout(1200);
  assert.equal(await list.inputValue(), "speed");
  await panel.getByRole("button", { name: "Set mode of joint 1", exact: true }).click();
  await until(async () => (await simJoint(studio.url, 1)).mode === 2, { what: "speed mode" });
  await list.selectOption("position");
  await panel.getByRole("button", { name: "Set mode of joint 1", exact: true }).click();
  await until(async () => (await simJoint(studio.url, 1)).mode === 3, { what: "position mode" });
});

test("a wCK servo: readouts, Passive, Hold, Preview", async () => {
  await panel.getByLabel("Device", { exact: true }).selectOption({ label: "Servo 0 · s0" });
  const steps = panel.getByLabel("Position (steps)");
  await until(async () => !Number.isNaN(await number(steps)), { what: "the servo's position" });
  assert.ok(!Number.isNaN(await number(panel.getByLabel("Angle (deg)"))));
  await panel.getByRole("button", { name: "Passive servo 0", exact: true }).click();
  await until(async () => (await simServo(studio.url, 0)).mode === "passive", { what: "servo 0 passive" });
  await panel.getByRole("button", { name: "Hold servo 0 at its position", exact: true }).click();
  await until(async () => (await simServo(studio.url, 0)).mode !== "passive", { what: "servo 0 holding" });
  const slider = panel.getByLabel("Jog target servo 0 (steps)");
  await slider.fill("150");
  await until(async () => (await simServo(studio.url, 0)).position >= 149, { timeout: 8000, what: "servo 0 at 150" });
  await screenshot(page, "device-wck");
  await panel.getByRole("button", { name: "Preview Passive servo 0", exact: true }).click();
  await until(async () => (await page.getByRole("tab", { name: "Preview" }).getAttribute("aria-selected")) === "true", {
    what: "the Preview tab",
  });
  await openTab(page, "Device");
});

test("Disarm brings the devices to the safe state and says so", async () => {
  await page.getByRole("button", { name: "Disarm", exact: true }).click();
  const banner = page.getByRole("alert").filter({ hasText: "Devices brought to the safe state" });
  await banner.waitFor({ timeout: 5000 });
  assert.equal(await panel.getByLabel("Jog target servo 0 (steps)").isDisabled(), true);
  await screenshot(page, "device-safe");
});

test("a servo that stops answering shows \"no reply\", not its old values", async () => {
  await panel.getByLabel("Device", { exact: true }).selectOption({ label: "Servo 1 · s1" });
  const steps = panel.getByLabel("Position (steps)");
  await until(async () => !Number.isNaN(await number(steps)), { what: "servo 1's position" });
  // Servo 1 moves to ID 25: nothing answers at ID 1 any more.
  await page.evaluate(() => window.studio.run({ op: "wck.set-id", id: 1, new_id: 25, confirm: true }));
  await until(async () => (await steps.textContent()) === "no reply", { what: "no reply" });
  assert.equal(await panel.getByLabel("Angle (deg)").textContent(), "no reply");
  await panel.getByText(/no reply: .*servo 1 did not answer/).waitFor();
  await screenshot(page, "device-no-reply");
});

test("no console errors", () => {
  assert.deepEqual(errors, []);
});
