//! A mixed robot from a TOML file: two wCK servos and two WHJ joints moved by the same
//! code, in radians, with soft limits, speed limits, a watchdog and a safe stop.
//!
//! ```text
//! cargo run -p robobus --example mixed_robot                         # simulators
//! cargo run -p robobus --example mixed_robot -- robot.toml --hardware # the real buses
//! ```
//!
//! The robot file (default `examples/robot.toml`) names the buses. Without
//! `--hardware` both buses are replaced by simulators, wired the way real links are:
//! the wCK simulator behind a pseudo-terminal (on Windows, which has none, on a TCP port of
//! 127.0.0.1), the WHJ simulator on the in-process CAN FD bus. Ctrl-C safe-stops the robot (wCK passive, WHJ hold) and ends the program.
#![allow(clippy::print_stdout)]

use std::error::Error;
use std::f64::consts::TAU;
use std::fmt::Write as _;
use std::time::Duration;

use robobus::robot::{BusConfig, Robot, RobotConfig, RobotError};
use robobus::wck::WckBus;
use robobus::whj::JointBus;
use robobus_sim::wck::{Bus, BusConfig as WckSimConfig, Endpoint, Model};
use robobus_sim::whj::{Served, WhjBus, WhjModel};
use robobus_wck::BaudRate;

/// Control cycles per second.
const RATE_HZ: f64 = 50.0;
/// How long the motion runs.
const RUN: Duration = Duration::from_secs(4);

/// The simulators behind the buses of the robot file (each stops when dropped).
struct Simulators {
    wck: Vec<Endpoint>,
    whj: Vec<Served>,
}

/// Serves a simulated wCK bus behind a pseudo-terminal; returns the simulator and the
/// client's side.
#[cfg(unix)]
fn serve_wck(sim: Bus) -> Result<(Endpoint, robobus_link::PtyLink), Box<dyn Error>> {
    Ok(robobus_sim::wck::spawn(sim)?)
}

/// Serves a simulated wCK bus on a TCP port of 127.0.0.1 (no pseudo-terminals here);
/// returns the simulator and the client's connection.
#[cfg(not(unix))]
fn serve_wck(sim: Bus) -> Result<(Endpoint, robobus_link::TcpByteLink), Box<dyn Error>> {
    use robobus_link::{PortSpec, TcpByteLink, WaitMode};
    let any_port = std::net::SocketAddr::from((std::net::Ipv4Addr::LOCALHOST, 0));
    let sim = robobus_sim::wck::spawn_tcp(sim, any_port, WaitMode::Sleep)?;
    let PortSpec::Tcp { host, port } = sim.path().to_string_lossy().parse()? else {
        return Err(format!("the simulator serves {}, not TCP", sim.path().display()).into());
    };
    let link = TcpByteLink::connect(&host, port, Duration::from_secs(2))?;
    Ok((sim, link))
}

/// Opens the robot with every bus replaced by a simulator holding the file's IDs.
fn simulated(config: &RobotConfig) -> Result<(Robot, Simulators), Box<dyn Error>> {
    let ids_on = |bus: &str| -> Vec<u8> {
        config
            .joints
            .iter()
            .filter(|j| j.bus == bus)
            .map(|j| j.id)
            .collect()
    };
    let mut sims = Simulators {
        wck: Vec::new(),
        whj: Vec::new(),
    };
    let mut builder = Robot::builder(config.clone());
    let mut woke = false;
    for (name, bus) in &config.buses {
        let ids = ids_on(name);
        if bus.is_wck() {
            let sim = Bus::with_servos(WckSimConfig::default(), Model::W1108, ids.clone());
            let (sim, link) = serve_wck(sim)?;
            println!(
                "bus {name}: simulated wCK servos {ids:?} on {}",
                sim.path().display()
            );
            sims.wck.push(sim);
            builder = builder.wck_bus(name.clone(), WckBus::new(link, BaudRate::B115200)?);
            woke = true;
        } else {
            let (sim, wire) =
                robobus_sim::whj::spawn(WhjBus::chain(ids.clone(), WhjModel::Whj30, 7))?;
            sims.whj.push(sim);
            println!("bus {name}: simulated WHJ joints {ids:?} on the in-process CAN FD bus");
            builder = builder.whj_bus(name.clone(), JointBus::open(wire.endpoint())?);
        }
    }
    if woke {
        std::thread::sleep(Duration::from_millis(70)); // wCK modules power up
    }
    Ok((builder.open()?, sims))
}

/// The motion: each joint swings around the middle of its limits (and the knee is asked
/// past its limit, to show the clamp).
fn targets(robot: &Robot, t: f64) -> Vec<f64> {
    robot
        .limits()
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let mid = 0.5 * (l.min_rad + l.max_rad);
            let amp = 0.6 * (l.max_rad - l.min_rad);
            mid + amp * (TAU * 0.5 * t + i as f64).sin()
        })
        .collect()
}

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .unwrap_or_else(|| concat!(env!("CARGO_MANIFEST_DIR"), "/examples/robot.toml").into());
    let hardware = args.any(|a| a == "--hardware");
    let config = RobotConfig::from_toml_file(&path)?;
    println!(
        "{path}: {} joints on {} buses, watchdog {:.0} ms",
        config.joints.len(),
        config.buses.len(),
        config.watchdog_timeout * 1e3
    );
    for (name, bus) in &config.buses {
        let family = if bus.is_wck() { "wCK" } else { "WHJ" };
        let detail = match bus {
            BusConfig::Wck { port, baud, .. } => format!("{port} at {baud} bit/s"),
            BusConfig::WhjCan { iface, .. } => format!("SocketCAN {iface}"),
            BusConfig::WhjUdp { .. } => "UDP multicast".into(),
            _ => "supplied by the program".into(),
        };
        println!(
            "  bus {name}: {family}, {detail}, safe state {:?}",
            bus.safe_state()
        );
    }

    let (mut robot, _sims) = if hardware {
        (Robot::open(config)?, None)
    } else {
        let (robot, sims) = simulated(&config)?;
        (robot, Some(sims))
    };
    // The program's one Ctrl-C / SIGTERM handler puts the robot in its safe state; the
    // next command then fails and the loop ends.
    let stop = robot.stop_handle();
    ctrlc::set_handler(move || {
        stop.interrupt();
    })?;

    let names = robot.joint_names().to_vec();
    // Paced on the robot's clock (its buses' clock: the wall clock here, a simulator's
    // virtual clock in a test).
    let period = Duration::from_secs_f64(1.0 / RATE_HZ);
    let start = robot.now();
    let mut next = start;
    let mut clamps = 0usize;
    let mut cycle = 0u64;
    while robot.now() - start < RUN {
        let t = (robot.now() - start).as_secs_f64();
        let report = match robot.command(&targets(&robot, t)) {
            Ok(r) => r,
            Err(RobotError::SafeStopped { cause }) => {
                println!("stopped: {cause}");
                return Ok(());
            }
            Err(e) => return Err(e.into()),
        };
        clamps += report.limited.len();
        if cycle.is_multiple_of(25) {
            let states = robot.read()?;
            let line: Vec<String> = names
                .iter()
                .zip(&states)
                .map(|(n, s)| {
                    let mut text = format!("{n} {:+.3} rad", s.position_rad);
                    if let Some(v) = s.velocity_rad_s {
                        let _ = write!(text, " {v:+.2} rad/s");
                    }
                    if let Some(a) = s.current_a {
                        let _ = write!(text, " {a:+.3} A");
                    }
                    text
                })
                .collect();
            println!("t = {t:4.2} s  {}", line.join(" | "));
        }
        cycle += 1;
        next += period;
        robot.sleep_until(next);
    }
    println!("{cycle} cycles, {clamps} targets limited (soft limits or speed)");

    // Stall on purpose: the watchdog puts the robot in its safe state.
    robot.sleep(robot.watchdog_timeout() * 2);
    if let Some(report) = robot.safe_stop_report() {
        println!(
            "{} after the last command; safe states applied in {:.1} ms{}",
            report.cause,
            report.applied_in.as_secs_f64() * 1e3,
            if report.errors.is_empty() {
                String::new()
            } else {
                format!(" (errors: {})", report.errors.join("; "))
            }
        );
    }
    Ok(())
}
