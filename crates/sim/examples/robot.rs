//! The simulated robot, in-process on the virtual clock: a wCK humanoid of 16 servos on a
//! 115200 bit/s bus and a 7-joint WHJ30 arm on a 1 / 5 Mbit/s CAN FD bus.
//!
//! It does what a first session with real hardware does, byte for byte as the devices
//! would see it: scan the wCK bus, play three keyframes as synchronized moves while polling
//! every servo, then wake the WHJ joints from their bootloader, enable them in position
//! mode and stream a 500 Hz sine trajectory with per-joint servo frames. It ends with what
//! moved, how well it tracked, and the bus figures.
//!
//! `cargo run --release -p robobus-sim --example robot`
#![allow(clippy::print_stdout)]

use std::time::{Duration, Instant};

use robobus_sim::wck::{Bus, BusConfig, Model, VirtualHost};
use robobus_sim::whj::{WhjBus, WhjModel};
use robobus_wck::{Command, Position, Reply, ServoId, SyncMove, TorqueLevel};
use robobus_whj::registers::WorkMode;
use robobus_whj::units::Position as JointPosition;
use robobus_whj::{JointId, Reply as JointReply, Request};

type AnyError = Box<dyn std::error::Error>;

const SERVOS: u8 = 16;
const JOINTS: u8 = 7;

fn main() -> Result<(), AnyError> {
    let wall = Instant::now();
    let wck = humanoid()?;
    let whj = arm()?;
    println!();
    println!(
        "simulated {:.1} s of wCK bus and {:.1} s of CAN FD bus in {:.2} s of wall-clock time",
        wck.as_secs_f64(),
        whj.as_secs_f64(),
        wall.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Reads one servo's status; `None` if nothing plausible came back.
fn status(host: &mut VirtualHost, id: ServoId, timeout: Duration) -> Option<Position> {
    let cmd = Command::StatusRead { id };
    let reply = host.transact(&cmd.encode(), cmd.reply_len(), timeout);
    match cmd.decode_reply(&reply) {
        Ok(Reply::Status { position, .. }) => Some(position),
        _ => None,
    }
}

fn humanoid() -> Result<Duration, AnyError> {
    println!("wCK humanoid: {SERVOS} x wCK-1108 on one 115200 bit/s bus");
    let bus = Bus::with_servos(BusConfig::default(), Model::W1108, 0..SERVOS);
    let mut host = VirtualHost::new(bus);
    host.sleep(Duration::from_millis(70)); // modules are deaf for 65 ms after power-up

    // Scan every ID with a short per-ID timeout, as a scanner does.
    let t0 = host.now();
    let mut found = Vec::new();
    for raw in 0..=ServoId::MAX.get() {
        let id = ServoId::new(raw)?;
        if status(&mut host, id, Duration::from_millis(3)).is_some() {
            found.push(raw);
        }
    }
    let scan = host.now().saturating_sub(t0);
    println!(
        "  scan   IDs 0..=30 in {:.1} ms: found {} servos ({:?})",
        scan.as_secs_f64() * 1e3,
        found.len(),
        found
    );

    // Three keyframes (stand, arms up, crouch), each a synchronized move, polled at 50 Hz.
    let keyframes: [(&str, [u8; SERVOS as usize]); 3] = [
        ("stand", [127; 16]),
        (
            "arms up",
            [
                200, 54, 190, 64, 127, 127, 127, 127, 127, 127, 127, 127, 127, 127, 127, 127,
            ],
        ),
        (
            "crouch",
            [
                127, 127, 127, 127, 90, 164, 80, 174, 100, 154, 110, 144, 127, 127, 127, 127,
            ],
        ),
    ];
    let torque = TorqueLevel::new(0)?;
    let mut polls = 0u32;
    for (name, pose) in keyframes {
        let positions = pose
            .iter()
            .map(|&p| Position::new(p))
            .collect::<Result<Vec<_>, _>>()?;
        let start = host.now();
        host.send(&Command::SyncMove(SyncMove::new(torque, &positions)?).encode());
        let mut settled = None;
        let mut worst = 0u8;
        while host.now().saturating_sub(start) < Duration::from_millis(800) {
            worst = 0;
            for (raw, target) in (0..SERVOS).zip(pose) {
                let at = status(&mut host, ServoId::new(raw)?, Duration::from_millis(5))
                    .ok_or("a servo stopped answering")?;
                polls += 1;
                worst = worst.max(at.get().abs_diff(target));
            }
            if worst <= 1 && settled.is_none() {
                settled = Some(host.now().saturating_sub(start));
            }
            host.sleep(Duration::from_millis(20));
        }
        match settled {
            Some(t) => println!(
                "  pose   {name:<8} all {SERVOS} servos within 1 step (1.06 deg) after {:>5.0} ms",
                t.as_secs_f64() * 1e3
            ),
            None => println!("  pose   {name:<8} still {worst} steps off after 800 ms"),
        }
    }
    let elapsed = host.now();
    let stats = host.bus().stats();
    let wire = robobus_wck::timing::wire_time(
        usize::try_from(stats.host_bytes + stats.received_bytes)?,
        robobus_wck::BaudRate::B115200,
    );
    println!(
        "  bus    {} status polls, {} bytes out, {} bytes back, {} decode errors; wire busy {:.1} %",
        polls,
        stats.host_bytes,
        stats.received_bytes,
        stats.decode_errors,
        100.0 * wire.as_secs_f64() / elapsed.as_secs_f64()
    );
    Ok(elapsed)
}

fn arm() -> Result<Duration, AnyError> {
    println!("WHJ arm: {JOINTS} x WHJ30 on one CAN FD bus (1 Mbit/s arbitration, 5 Mbit/s data)");
    let mut bus = WhjBus::chain(1..=JOINTS, WhjModel::Whj30, 7);
    let joints = (1..=JOINTS)
        .map(JointId::new)
        .collect::<Result<Vec<_>, _>>()?;

    // The usage demo's start-up: leave the bootloader, position mode, enable.
    for &j in &joints {
        for req in [
            Request::start_application(j),
            Request::set_mode(j, WorkMode::Position),
            Request::enable(j, true),
        ] {
            let replies = bus.request(req.to_frame());
            let ok = replies.iter().any(|d| {
                matches!(
                    JointReply::from_frame(&d.frame),
                    Ok(JointReply::WriteAck { .. })
                )
            });
            if !ok {
                return Err(format!("joint {} did not acknowledge {req:?}", j.get()).into());
            }
        }
    }
    bus.advance(Duration::from_millis(50));
    println!("  start  {JOINTS} joints out of the bootloader, position mode, enabled");

    // 500 Hz sine: 20 deg amplitude, 0.5 Hz, each joint a little out of phase.
    let period = Duration::from_millis(2);
    let cycles = 2000u32;
    let start = bus.now();
    let busy0 = bus.stats().busy;
    let mut last_target = vec![0.0f64; joints.len()];
    let mut err_sq = vec![0.0f64; joints.len()];
    let mut err_max = vec![0.0f64; joints.len()];
    let mut feedback = 0u32;
    for k in 0..cycles {
        let t = start + period * k;
        let secs = (period * k).as_secs_f64();
        for (i, &j) in joints.iter().enumerate() {
            let phase = i as f64 * 0.4;
            let deg =
                20.0 * (std::f64::consts::TAU * 0.5 * secs + phase).sin() - 20.0 * phase.sin();
            let target = JointPosition::from_degrees(deg)?;
            bus.submit(Request::PositionServo { joint: j, target }.to_frame(), t);
        }
        for d in bus.run_until(t + period) {
            if let Ok(JointReply::ServoFeedback {
                joint,
                feedback: fb,
            }) = JointReply::from_frame(&d.frame)
            {
                let i = usize::from(joint.get() - 1);
                // Feedback is sampled before the new target takes effect: compare it with
                // the target of the cycle before.
                let e = (fb.position.degrees() - last_target[i]).abs();
                err_sq[i] += e * e;
                err_max[i] = f64::max(err_max[i], e);
                feedback += 1;
            }
        }
        for (i, target) in last_target.iter_mut().enumerate() {
            let phase = i as f64 * 0.4;
            *target =
                20.0 * (std::f64::consts::TAU * 0.5 * secs + phase).sin() - 20.0 * phase.sin();
        }
    }
    let run = bus.now().saturating_sub(start);
    let busy = bus.stats().busy.saturating_sub(busy0);
    println!(
        "  sine   {cycles} cycles at 500 Hz, {feedback} of {} feedback frames received",
        cycles * u32::from(JOINTS)
    );
    for (i, &j) in joints.iter().enumerate() {
        let rms = (err_sq[i] / f64::from(cycles)).sqrt();
        let state = bus.joint(j.get()).ok_or("joint vanished")?.state();
        println!(
            "         joint {}: tracking error rms {rms:.3} deg, max {:.3} deg; {:.2} A, {:.1} degC, {}",
            j.get(),
            err_max[i],
            state.current_a,
            state.temperature_c,
            state.error
        );
    }
    println!(
        "  bus    {:.1} % busy at 500 Hz (14 frames per cycle; the wire allows about {:.0} Hz)",
        100.0 * busy.as_secs_f64() / run.as_secs_f64(),
        500.0 * run.as_secs_f64() / busy.as_secs_f64()
    );
    Ok(bus.now())
}
