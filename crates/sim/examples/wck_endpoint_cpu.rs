//! Measures the CPU the pty endpoint uses serving 31 wCK servos at 115200 bit/s in real
//! time, under continuous polling by a client on the pty's slave side, and how close the
//! client gets to the modelled transaction rate.
//!
//! `cargo run --release -p robobus-sim --example wck_endpoint_cpu [seconds]`

#[cfg(not(target_os = "linux"))]
fn main() {}

#[cfg(target_os = "linux")]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    use std::io::Write as _;
    use std::time::{Duration, Instant};

    use robobus_link::{ByteLink, PtyOptions, PtyPair};
    use robobus_sim::wck::{Bus, BusConfig, Endpoint, Model};

    let seconds = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(10u64);
    let mut out = std::io::stdout().lock();

    // Idle: 31 servos holding their position, nobody talking.
    {
        let pair = PtyPair::open(&PtyOptions::default())?;
        let mut bus = Bus::with_servos(BusConfig::default(), Model::W1108, 0..31);
        let sync = robobus_wck::SyncMove::new(
            robobus_wck::TorqueLevel::new(0)?,
            &[robobus_wck::Position::new(127)?; 31],
        )?;
        bus.advance(Duration::from_millis(70));
        let end = bus.host_send(
            Duration::from_millis(70),
            robobus_wck::Command::SyncMove(sync).encode().as_bytes(),
        );
        bus.advance(end);
        let endpoint = Endpoint::spawn(bus, pair.master, pair.slave_path.clone())?;
        std::thread::sleep(Duration::from_secs(3));
        let stats = endpoint.stop()?;
        writeln!(
            out,
            "idle, 31 servos holding position: endpoint thread CPU {:.2} % of one core",
            100.0 * stats.cpu.as_secs_f64() / stats.wall.as_secs_f64()
        )?;
    }

    let pair = PtyPair::open(&PtyOptions::default())?;
    let bus = Bus::with_servos(BusConfig::default(), Model::W1108, 0..31);
    let endpoint = Endpoint::spawn(bus, pair.master, pair.slave_path.clone())?;
    let mut client = pair.slave;
    std::thread::sleep(Duration::from_millis(80));

    let start = Instant::now();
    let mut transactions = 0u64;
    let mut good = 0u64;
    let mut buf = [0u8; 2];
    while start.elapsed() < Duration::from_secs(seconds) {
        let id = u8::try_from(transactions % 31)?;
        let d1 = 0xA0 | id;
        client.write_all(&[0xFF, d1, 0x00, d1 & 0x7F])?;
        if client
            .read_exact(&mut buf, Instant::now() + Duration::from_millis(50))
            .is_ok()
        {
            good += u64::from(buf == [0x00, 0x7F]);
        }
        transactions += 1;
    }
    let elapsed = start.elapsed().as_secs_f64();
    let stats = endpoint.stop()?;
    writeln!(
        out,
        "31 servos at 115200 bit/s behind a pty, continuous polling for {elapsed:.1} s"
    )?;
    writeln!(
        out,
        "endpoint thread CPU: {:.3} s of {:.3} s = {:.2} % of one core",
        stats.cpu.as_secs_f64(),
        stats.wall.as_secs_f64(),
        100.0 * stats.cpu.as_secs_f64() / stats.wall.as_secs_f64()
    )?;
    let rate = transactions as f64 / elapsed;
    writeln!(
        out,
        "{transactions} transactions ({good} correct), {rate:.1}/s = {:.1} % of the modelled \
         654.7/s (wire + 1006.6 us turnaround)",
        100.0 * rate / 654.7
    )?;
    let mean = stats.late_total.as_secs_f64() * 1e6 / stats.bytes_out.max(1) as f64;
    writeln!(
        out,
        "reply bytes written {mean:.1} us after their release instant on average, {:?} at most",
        stats.late_max
    )?;
    Ok(())
}
