//! Synchronized motion of six wCK servos: a travelling sine wave sent with one
//! synchronized-move packet per cycle, with the servos read back now and then.
//!
//! ```text
//! cargo run -p robobus --example wck_sync_motion                 # in-process simulator
//! cargo run -p robobus --example wck_sync_motion -- /dev/ttyUSB0 # a real bus (IDs 0..=5)
//! ```
//!
//! With a path, it opens that serial port at 115200 bit/s (a USB adapter, or the pty of
//! `robobus sim wck`); without one it starts a simulated bus of six servos behind a
//! pseudo-terminal and talks to it through that pty, exactly like a port.
#![allow(clippy::print_stdout)]

use std::error::Error;
use std::f64::consts::TAU;
use std::fmt::Write as _;
use std::time::{Duration, Instant};

use robobus::wck::WckBus;
use robobus_link::ByteLink;
use robobus_wck::{BaudRate, Position, ServoId, TorqueLevel, timing};

/// Servos 0..SERVOS.
const SERVOS: u8 = 6;
/// Sync-move packets per second.
const RATE_HZ: f64 = 50.0;
/// How long the wave runs.
const RUN: Duration = Duration::from_secs(3);
/// Wave: centre, amplitude (steps of 1.055°), frequency (Hz), phase step between servos.
const CENTRE: f64 = 127.0;
const AMPLITUDE: f64 = 50.0;
const FREQUENCY_HZ: f64 = 0.5;
const PHASE_STEP: f64 = TAU / 6.0;

fn target(servo: u8, t: f64) -> Result<Position, Box<dyn Error>> {
    let angle = TAU * FREQUENCY_HZ * t + f64::from(servo) * PHASE_STEP;
    let p = (CENTRE + AMPLITUDE * angle.sin()).round().clamp(0.0, 254.0);
    // Rounded and clamped to 0..=254 above.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    Ok(Position::new(p as u8)?)
}

fn run<L: ByteLink>(bus: &mut WckBus<L>) -> Result<(), Box<dyn Error>> {
    let torque = TorqueLevel::new(0)?;
    let period = Duration::from_secs_f64(1.0 / RATE_HZ);
    let wire = timing::sync_move_time(usize::from(SERVOS), bus.baud());
    println!(
        "{} servos, sync move every {:.1} ms ({:.0} µs on the wire at {})",
        SERVOS,
        period.as_secs_f64() * 1e3,
        wire.as_secs_f64() * 1e6,
        bus.baud()
    );
    let start = Instant::now();
    let mut next = start;
    let mut cycles = 0u32;
    let mut late = 0u32;
    while start.elapsed() < RUN {
        let t = start.elapsed().as_secs_f64();
        let targets = (0..SERVOS)
            .map(|i| target(i, t))
            .collect::<Result<Vec<_>, _>>()?;
        bus.sync_move(torque, &targets)?;
        cycles += 1;
        // Twice a second: read every servo back (6 status reads, about 9 ms at 115200).
        if cycles.is_multiple_of(25) {
            let mut line = format!("t = {t:4.2} s  target/actual:");
            for (i, want) in (0..SERVOS).zip(&targets) {
                let status = bus.servo(ServoId::new(i)?).status()?;
                write!(line, " {:3}/{:3}", want.get(), status.position.get())?;
            }
            println!("{line}");
        }
        next += period;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else {
            late += 1;
        }
    }
    let elapsed = start.elapsed().as_secs_f64();
    // Back to the centre, all at once.
    let centre = Position::new(127)?;
    bus.sync_move(torque, &[centre; SERVOS as usize])?;
    let stats = bus.stats();
    println!(
        "{cycles} sync moves in {elapsed:.2} s ({:.1} Hz), {late} late; {} transactions, \
         {} retries, {} timeouts",
        f64::from(cycles) / elapsed,
        stats.attempts,
        stats.retries,
        stats.timeouts
    );
    Ok(())
}

#[cfg(target_os = "linux")]
fn simulated() -> Result<(), Box<dyn Error>> {
    use robobus_sim::wck::{Bus, BusConfig, Model, spawn};

    let (sim, link) = spawn(Bus::with_servos(
        BusConfig::default(),
        Model::W1108,
        0..SERVOS,
    ))?;
    println!("simulated wCK bus on {}", sim.path().display());
    std::thread::sleep(robobus_wck::timing::POWER_UP_DEAF + Duration::from_millis(5));
    let mut bus =
        WckBus::new(link, BaudRate::B115200)?.with_device_name(sim.path().display().to_string());
    run(&mut bus)?;
    let served = sim.stop()?;
    println!(
        "simulator: {} bytes in, {} out, latest reply byte {:?} after its wire time",
        served.bytes_in, served.bytes_out, served.late_max
    );
    Ok(())
}

#[cfg(not(target_os = "linux"))]
fn simulated() -> Result<(), Box<dyn Error>> {
    Err("the in-process simulator needs Linux; pass a serial port path".into())
}

fn main() -> Result<(), Box<dyn Error>> {
    match std::env::args().nth(1) {
        Some(path) => {
            let mut bus = WckBus::open(&path, BaudRate::B115200)?;
            run(&mut bus)
        }
        None => simulated(),
    }
}
