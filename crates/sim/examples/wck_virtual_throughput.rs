//! Measures how fast the virtual clock runs: 31 wCK servos at 115200 bit/s under
//! continuous polling (status reads one after the other, as fast as the wire and the
//! turnaround allow), with every servo moving, for 60 simulated seconds.
//!
//! `cargo run --release -p robobus-sim --example wck_virtual_throughput`

use std::io::Write as _;
use std::time::{Duration, Instant};

use robobus_sim::wck::{Bus, BusConfig, Model, VirtualHost};
use robobus_wck::{Command, Position, ServoId, SyncMove, TorqueLevel};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let sim_seconds = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(60u64);
    let bus = Bus::with_servos(BusConfig::default(), Model::W1108, 0..31);
    let mut host = VirtualHost::new(bus);
    host.sleep(Duration::from_millis(70));
    if std::env::var_os("MECH_ONLY").is_some() {
        let w = Instant::now();
        host.sleep(Duration::from_secs(sim_seconds));
        writeln!(
            std::io::stdout(),
            "mechanics only: {:.3} s wall",
            w.elapsed().as_secs_f64()
        )?;
        return Ok(());
    }
    let wall = Instant::now();
    let end = host.now() + Duration::from_secs(sim_seconds);
    let mut transactions = 0u64;
    let mut replies = 0u64;
    let mut flip = false;
    while host.now() < end {
        // Every second, send everyone to the other end (so the mechanics work too).
        if transactions.is_multiple_of(600) {
            flip = !flip;
            let p = Position::new(if flip { 40 } else { 210 })?;
            let sync = SyncMove::new(TorqueLevel::new(0)?, &[p; 31])?;
            host.command(&Command::SyncMove(sync));
        }
        let id = ServoId::new(u8::try_from(transactions % 31)?)?;
        let reply = host.command(&Command::StatusRead { id });
        replies += u64::from(reply.len() == 2);
        transactions += 1;
    }
    let wall = wall.elapsed().as_secs_f64();
    let simulated = sim_seconds as f64;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "31 servos at 115200 bit/s, continuous status polling, all moving"
    )?;
    writeln!(
        out,
        "simulated {simulated:.0} s in {wall:.3} s of wall time"
    )?;
    writeln!(
        out,
        "=> {:.1} simulated seconds per wall-clock second",
        simulated / wall
    )?;
    writeln!(
        out,
        "{transactions} transactions ({replies} answered), {:.1} per simulated second \
         (model: 1 / (60/115200 + 1006.6 us) = 654.7)",
        transactions as f64 / simulated
    )?;
    Ok(())
}
