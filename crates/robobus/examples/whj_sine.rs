//! Seven WHJ joints follow sine trajectories at 500 Hz, against the simulator.
//!
//! The simulator serves a 7-joint WHJ30 chain on an in-process CAN FD bus on its own
//! thread; the client opens a `JointBus` on another endpoint of the same bus, connects
//! every joint (IAP release, identify), enables it in position mode and runs the cyclic
//! loop at 2 ms. Every cycle the next set-points are computed from the cycle's scheduled
//! time; the loop's statistics are printed at the end.
//!
//! ```text
//! cargo run -p robobus --example whj_sine -- [seconds] [--broadcast]
//! ```

// An example program: printing its results is its purpose.
#![allow(clippy::print_stdout)]

use std::error::Error;
use std::f64::consts::TAU;
use std::time::Duration;

use robobus::whj::{CyclicConfig, CyclicStats, JointBus, MotionLimits, Protocol};
use robobus_sim::whj::{WhjBus, WhjModel, spawn};
use robobus_whj::units::Position;
use robobus_whj::{JointId, WorkMode};

/// Sine amplitude, degrees.
const AMPLITUDE_DEG: f64 = 15.0;
/// Sine frequency, Hz.
const FREQUENCY_HZ: f64 = 0.5;
/// Cycle period: 500 Hz.
const PERIOD: Duration = Duration::from_millis(2);

fn main() -> Result<(), Box<dyn Error>> {
    let mut seconds = 4.0f64;
    let mut protocol = Protocol::PointToPoint;
    for arg in std::env::args().skip(1) {
        if arg == "--broadcast" {
            protocol = Protocol::Broadcast;
        } else {
            seconds = arg.parse().map_err(|_| {
                format!("expected a duration in seconds or --broadcast, got {arg:?}")
            })?;
        }
    }

    // The simulator: seven WHJ30 joints (IDs 1..=7) served on the wall clock.
    let (sim, wire) = spawn(WhjBus::chain(1..=7, WhjModel::Whj30, 1))?;

    let bus = JointBus::open(wire.endpoint())?;
    let joints: Vec<JointId> = (1..=7).map(JointId::new).collect::<Result<_, _>>()?;
    for &id in &joints {
        let joint = bus.joint(id)?;
        let identity = joint.identity()?;
        println!(
            "{id}: {} firmware {} unique ID {}",
            identity.model, identity.firmware, identity.unique_id
        );
        joint.disable()?;
        joint.set_mode(WorkMode::Position)?;
        joint.enable()?;
    }

    let cyc = bus.cyclic(CyclicConfig {
        protocol,
        // Fast enough to follow the sine (peak 47 °/s, 148 °/s²), smooth at the start.
        smooth: Some(MotionLimits {
            max_speed_deg_s: 90.0,
            max_accel_deg_s2: 600.0,
            ..MotionLimits::default()
        }),
        ..CyclicConfig::position(joints.clone(), PERIOD)
    })?;
    let start = cyc
        .next_report(Duration::from_secs(1))
        .ok_or("the loop produced no cycle")?
        .scheduled;
    let mut worst_error = 0.0f64;
    let mut previous: Option<Vec<i32>> = None;
    loop {
        let Some(report) = cyc.next_report(Duration::from_millis(100)) else {
            continue;
        };
        let t = report.scheduled.duration_since(start).as_secs_f64();
        if t > seconds {
            break;
        }
        // Feedback is the position when this cycle's command arrived: compare it with the
        // set-point of the cycle before.
        if let Some(prev) = &previous
            && t > 0.5
        {
            for (fb, cmd) in report.feedback.iter().zip(prev) {
                if let Some(fb) = fb {
                    let err = (fb.position.degrees() - Position(*cmd).degrees()).abs();
                    worst_error = worst_error.max(err);
                }
            }
        }
        previous = Some(report.commanded.clone());
        let targets = (0..joints.len())
            .map(|i| {
                let phase = TAU * f64::from(u8::try_from(i).unwrap_or(0)) / 7.0;
                Position::from_degrees(AMPLITUDE_DEG * (TAU * FREQUENCY_HZ * t + phase).sin())
            })
            .collect::<Result<Vec<_>, _>>()?;
        cyc.set_positions(&targets)?;
    }
    let stats = cyc.stop();
    print_stats(protocol, seconds, &stats, worst_error);
    for &id in &joints {
        bus.joint_unchecked(id).disable()?;
    }
    drop(bus);
    let (_, served) = sim.stop()?;
    println!(
        "  simulator: {} frames in, {} out, worst reply lateness {:?}",
        served.received, served.sent, served.max_lateness
    );
    Ok(())
}

fn print_stats(protocol: Protocol, seconds: f64, stats: &CyclicStats, worst_error: f64) {
    println!("{protocol:?}, 7 joints, {PERIOD:?} period, {seconds} s:");
    println!(
        "  cycles {} complete {} deadline misses {} missing replies {} overruns {}",
        stats.cycles, stats.complete, stats.deadline_misses, stats.missing_replies, stats.overruns
    );
    let p = stats.round_trip;
    println!(
        "  round trip p50 {:?} p90 {:?} p99 {:?} max {:?}",
        p.p50, p.p90, p.p99, p.max
    );
    let l = stats.start_lateness;
    println!(
        "  start lateness p50 {:?} p99 {:?} max {:?}",
        l.p50, l.p99, l.max
    );
    println!(
        "  largest tracking error {worst_error:.3}° (set-point one cycle earlier vs feedback)"
    );
}
