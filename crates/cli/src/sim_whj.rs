//! `robobus sim whj`: simulated WHJ joints on a virtual CAN FD bus, served until
//! interrupted (Ctrl-C / SIGTERM).
//!
//! `--bus udp` joins python-can's `udp_multicast` bus (group 239.74.163.2, port 43113) on
//! the loopback interface; `--bus udp:GROUP:PORT` picks another group; any other value is
//! a `SocketCAN` interface (`vcan0`, `can0`; Linux only). `--bus slcan:PATH` presents an
//! emulated slcan CAN FD adapter (`CANable` 2.0 class) with the joints behind it on a pty
//! at PATH, `--bus slcan:socket://127.0.0.1:PORT` on TCP (every OS): clients open it as
//! they open a real adapter (`--bus slcan:PATH`, python-can's `slcan` interface).
//! `--bus fdcanusb:PATH` (or `fdcanusb:socket://127.0.0.1:PORT`) does the same with an
//! emulated mjbots fdcanusb.

use std::time::Duration;

use anyhow::Context;
use robobus::ops::IdList;
use robobus::ops::capture::{Overwrite, capture_frame_link};
use robobus_link::{FaultyFrameLink, FrameLink, FrameLinkSpec, PortSpec, TcpServer};
#[cfg(unix)]
use robobus_link::{LinkError, PtyOptions, PtyPair, PtySymlink};
use robobus_sim::faults::{DeviceFaultKind, FaultSchedule};
use robobus_sim::whj::adapter::{self, AdapterModel, FdcanusbAdapter, SerialTime, SlcanAdapter};
use robobus_sim::whj::{JointConfig, WhjBus, WhjModel, WhjSimLink, serve_observed};
use robobus_whj::JointId;
use robobus_whj::timing::BitRates;

use crate::exit::usage;
use crate::hand::Hand;
use crate::sim_wck::{LinkFaultArgs, device_faults};

/// What `robobus sim whj --help` adds after the options.
const AFTER_LONG_HELP: &str = "\
Readiness: the line \"serving ...\" appears on stderr once the simulator takes frames;
nothing a client sends from then on is missed.

Faults: --drop / --corrupt / --duplicate / --truncate / --delay / --disconnect-after act
on every frame (both directions) through the link layer's seeded fault injector: the same
--fault-seed and the same traffic give the same faults. --fault-error, --fault-silent and
--fault-power-cycle act on one joint at a time, SECONDS after serving starts (repeat them
for more).

slcan: with --bus slcan:PATH the joints sit behind an emulated slcan adapter whose
channel the client opens and sets to its rates (S / Y commands); --bitrate / --dbitrate
are then the adapter's rates at power-up, which it must be able to take (nominal 10k..1M,
data 2M or 5M). Every character costs 10 µs each way on the adapter's serial link, as on
a USB full-speed adapter, on top of the CAN wire time.

fdcanusb: with --bus fdcanusb:PATH the joints sit behind an emulated mjbots fdcanusb,
off the bus until the client sends `can on`; the client sets its rates with `conf set`
(--bitrate / --dbitrate are what it powers up configured to). Its text lines cost the
same 10 µs a character each way.";

/// Options of `robobus sim whj`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = AFTER_LONG_HELP)]
pub(crate) struct Args {
    /// Node IDs of the simulated joints: a range `1-7`, a list `1,2,5`, or both `1-3,9`.
    #[arg(long, default_value = "1-7", value_parser = parse_joints)]
    joints: JointIds,
    /// Product: whj03, whj10 (= whj10b), whj10n, whj30, whj60, whj120.
    #[arg(long, default_value = "whj30")]
    model: WhjModel,
    /// Record every frame the simulated joints receive and send to FILE as a candump log
    /// (`candump -L`'s format; `robobus replay FILE` decodes it). An existing FILE is not
    /// overwritten.
    #[arg(long, value_name = "FILE")]
    capture: Option<std::path::PathBuf>,
    /// The bus: `udp` (python-can `udp_multicast`, 239.74.163.2:43113), `udp:GROUP:PORT`,
    /// a `SocketCAN` interface such as `vcan0`, or `slcan:PATH` / `slcan:socket://IP:PORT`
    /// (an emulated slcan adapter on a pty at PATH or on TCP), or `fdcanusb:PATH` /
    /// `fdcanusb:socket://IP:PORT` (an emulated mjbots fdcanusb).
    #[arg(long, default_value = "udp", value_parser = parse_bus)]
    bus: FrameLinkSpec,
    /// Seed of the simulated measurement noise (same seed, same noise).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Standard deviation of the measured-current noise in mA (0 = exact values; the
    /// usage demo shows a few mA at standstill).
    #[arg(long, default_value_t = 5.0)]
    current_noise_ma: f64,
    /// The bus's arbitration bit rate (the adapter's), bit/s: only the joints whose saved
    /// rates (0x08 / 0x09, taken at power-up) are the bus's hear and answer.
    #[arg(long, default_value_t = 1_000_000)]
    bitrate: u32,
    /// The bus's data bit rate, bit/s.
    #[arg(long, default_value_t = 5_000_000)]
    dbitrate: u32,
    /// A hand holds joint ID's output and moves it back and forth between FROM and TO
    /// degrees once every PERIOD seconds, as someone teaching a robot does:
    /// `ID:FROM:TO:PERIOD`, e.g. `1:-30:30:4`. Only a limp joint follows it (current
    /// mode at a small current, as `robobus robot teach` sets); a braked or
    /// position-holding one does not. Repeatable.
    #[arg(long, value_name = "ID:FROM:TO:PERIOD", allow_negative_numbers = true)]
    hand: Vec<String>,
    /// Joint ID's drive gives at most AMPS (A), whatever its current limit register says:
    /// `ID:AMPS`, e.g. `2:0.3`. It then falls behind position targets that need more, as a
    /// loaded joint or one on a weak supply does (to try how moves and waves handle a
    /// lagging joint). Repeatable.
    #[arg(long, value_name = "ID:AMPS")]
    weak_drive: Vec<String>,
    /// Put an end board on the bus too: it answers the end-board field of broadcast
    /// frames (0xF7 / 0x87) with its own small register map.
    #[arg(long)]
    end_board: bool,
    /// Boot straight into the application instead of waiting for `IAP_FLAG := 0`.
    #[arg(long)]
    no_iap: bool,
    /// Time a joint needs from receiving a frame to having its reply ready, µs.
    #[arg(long, default_value_t = 20)]
    processing_delay_us: u64,
    /// Initial output angle of every joint, degrees.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    initial_deg: f64,
    /// Probability that a frame (either direction) is lost.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    drop: f64,
    /// Probability that a frame (either direction) has one payload bit flipped.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    corrupt: f64,
    #[command(flatten)]
    faults: LinkFaultArgs,
    /// Joint latches error BITS (e.g. 0x4000) SECONDS after serving starts:
    /// `JOINT:BITS@SECONDS`, e.g. `1:0x4000@2.5`. Repeatable.
    #[arg(long, value_name = "JOINT:BITS@SECONDS")]
    fault_error: Vec<String>,
    /// Joint stops answering (until power-cycled) SECONDS after serving starts:
    /// `JOINT@SECONDS`. Repeatable.
    #[arg(long, value_name = "JOINT@SECONDS")]
    fault_silent: Vec<String>,
    /// Joint browns out (power-cycled: RAM lost, back in the bootloader unless --no-iap)
    /// SECONDS after serving starts: `JOINT@SECONDS`. Repeatable.
    #[arg(long, value_name = "JOINT@SECONDS")]
    fault_power_cycle: Vec<String>,
}

/// Parsed `--joints`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct JointIds(pub(crate) Vec<u8>);

pub(crate) fn parse_joints(s: &str) -> Result<JointIds, String> {
    let ids: IdList<JointId> = s.parse()?;
    Ok(JointIds(
        ids.sorted().as_slice().iter().map(|j| j.get()).collect(),
    ))
}

fn parse_bus(s: &str) -> Result<FrameLinkSpec, String> {
    s.parse()
        .map_err(|e: robobus_link::SpecError| e.to_string())
}

/// Largest current noise a simulated joint takes, mA (ten amperes of noise is no joint).
const MAX_CURRENT_NOISE_MA: f64 = 10_000.0;

/// Longest processing delay a simulated joint takes, µs (a joint answers within a
/// millisecond; 100 ms is already a dead one).
const MAX_PROCESSING_DELAY_US: u64 = 100_000;

/// Refuses a noise, start angle or delay no joint has, before anything is opened.
fn check_ranges(args: &Args) -> anyhow::Result<()> {
    if !(args.current_noise_ma.is_finite()
        && (0.0..=MAX_CURRENT_NOISE_MA).contains(&args.current_noise_ma))
    {
        return Err(usage(format!(
            "--current-noise-ma {} out of range (allowed: 0..={MAX_CURRENT_NOISE_MA})",
            args.current_noise_ma
        )));
    }
    // A joint starts inside its position limits (the simulated joints' are the defaults).
    let (min, max) = JointConfig::new(1, args.model).position_limits_deg;
    if !(args.initial_deg.is_finite() && (min..=max).contains(&args.initial_deg)) {
        return Err(usage(format!(
            "--initial-deg {} out of range (allowed: {min}..={max}, the joints' position \
             limits)",
            args.initial_deg
        )));
    }
    if args.processing_delay_us > MAX_PROCESSING_DELAY_US {
        return Err(usage(format!(
            "--processing-delay-us {} out of range (allowed: 0..={MAX_PROCESSING_DELAY_US})",
            args.processing_delay_us
        )));
    }
    Ok(())
}

/// `--weak-drive ID:AMPS`: a joint of `ids` and a current from 0 to the model's peak.
fn parse_weak_drive(text: &str, ids: &[u8], model: WhjModel) -> anyhow::Result<(u8, f64)> {
    let peak = JointConfig::new(1, model).params.peak_current_a();
    let bad = |why: String| usage(format!("--weak-drive {text}: {why} (ID:AMPS, e.g. 2:0.3)"));
    let Some((id, amps)) = text.split_once(':') else {
        return Err(bad("two fields".into()));
    };
    let id: u8 = id
        .trim()
        .parse()
        .map_err(|_| bad("the ID is not a number".into()))?;
    if !ids.contains(&id) {
        return Err(bad("no simulated joint has this ID".into()));
    }
    let amps = amps
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|a| a.is_finite() && (0.0..=peak).contains(a))
        .ok_or_else(|| {
            bad(format!(
                "AMPS out of range 0..={peak:.3} (the model's peak)"
            ))
        })?;
    Ok((id, amps))
}

/// The device faults the options schedule.
fn faults_of(args: &Args) -> anyhow::Result<Vec<robobus_sim::faults::DeviceFault>> {
    device_faults(
        &[
            (
                "--fault-error",
                DeviceFaultKind::Error(0),
                &args.fault_error,
            ),
            (
                "--fault-silent",
                DeviceFaultKind::Silent,
                &args.fault_silent,
            ),
            (
                "--fault-power-cycle",
                DeviceFaultKind::PowerCycle,
                &args.fault_power_cycle,
            ),
        ],
        1..=30,
        &args.joints.0,
    )
}

/// The simulated joints the options describe, on a bus at the options' rates (which an
/// emulated adapter must be able to take).
fn simulated_bus(args: &Args) -> anyhow::Result<(WhjBus, BitRates)> {
    let weak = args
        .weak_drive
        .iter()
        .map(|w| parse_weak_drive(w, &args.joints.0, args.model))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let configs = args.joints.0.iter().map(|&id| {
        let mut cfg = JointConfig::new(id, args.model);
        cfg.drive_current_limit_a = weak.iter().rev().find(|(w, _)| *w == id).map(|w| w.1);
        cfg.current_noise_ma = args.current_noise_ma;
        cfg.boot.wait_for_iap_flag = !args.no_iap;
        cfg.processing_delay = Duration::from_micros(args.processing_delay_us);
        cfg.initial_position_deg = args.initial_deg;
        cfg
    });
    let rates = robobus::ops::whj::rates::check_rates(args.bitrate, args.dbitrate)
        .map_err(|e| usage(e.to_string()))?;
    if matches!(args.bus, FrameLinkSpec::Slcan { .. }) {
        SlcanAdapter::check_rates(rates).map_err(|e| {
            usage(format!(
                "--bitrate / --dbitrate with --bus {}: {e}",
                args.bus
            ))
        })?;
    }
    let mut bus = WhjBus::with_configs(configs, args.seed).with_rates(rates);
    if args.end_board {
        bus = bus.with_end_board();
    }
    Ok((bus, rates))
}

pub(crate) fn run(args: &Args, dry_run: bool) -> anyhow::Result<()> {
    check_ranges(args)?;
    let wire_faults =
        args.faults
            .config(args.seed, ("drop", args.drop), ("corrupt", args.corrupt))?;
    let device = faults_of(args)?;
    let hands = args
        .hand
        .iter()
        .map(|h| Hand::parse(h, &args.joints.0, 360.0))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let (mut bus, rates) = simulated_bus(args)?;
    if dry_run {
        // A dry run opens nothing: no bus joined, no socket.
        let ids: Vec<String> = args.joints.0.iter().map(u8::to_string).collect();
        crate::output::print(&format!(
            "# would serve {} simulated {} joint(s) [{}] on {}{}; nothing opened\n",
            ids.len(),
            args.model,
            ids.join(","),
            args.bus.describe(),
            if args.end_board {
                ", with an end board"
            } else {
                ""
            }
        ))?;
        return Ok(());
    }
    if let FrameLinkSpec::Slcan { port, .. } = &args.bus {
        let adapter = SlcanAdapter::new(rates, SerialTime::default());
        return serve_adapter(
            args,
            bus,
            Box::new(adapter),
            port,
            wire_faults,
            device,
            &hands,
        );
    }
    if let FrameLinkSpec::Fdcanusb { port } = &args.bus {
        let adapter = FdcanusbAdapter::new(rates, SerialTime::default());
        return serve_adapter(
            args,
            bus,
            Box::new(adapter),
            port,
            wire_faults,
            device,
            &hands,
        );
    }
    let mut link = args.bus.open()?;
    if let Some(faults) = wire_faults {
        link = Box::new(FaultyFrameLink::new(link, faults));
    }
    if let Some(path) = &args.capture {
        // What the simulated joints received and sent, as candump logs it.
        let iface = args.bus.candump_iface();
        link = Box::new(capture_frame_link(link, path, iface, Overwrite::No)?);
    }

    // The command's one Ctrl-C / SIGTERM handler (`interrupt`), installed now.
    let token = crate::interrupt::stop_token();
    let stop = token.flag();

    let ids: Vec<String> = args.joints.0.iter().map(u8::to_string).collect();
    let announce = || {
        eprintln!(
            "robobus sim whj: serving {} joint(s) [{}] ({}) on {}; Ctrl-C to stop",
            ids.len(),
            ids.join(","),
            args.model,
            args.bus.describe()
        );
    };
    let t0 = std::time::Instant::now();
    let stats = serve_observed(
        &mut bus,
        &mut *link,
        stop,
        FaultSchedule::new(device),
        announce,
        |bus| {
            let t = t0.elapsed().as_secs_f64();
            for h in &hands {
                if let Some(j) = bus.joint_mut(h.id) {
                    j.set_hand(Some(h.angle(t)));
                }
            }
        },
    )
    .context("serving the simulated bus")?;
    eprintln!(
        "robobus sim whj: stopped after {:.3} s: {} frames in, {} frames out, max lateness {} µs",
        bus.now().as_secs_f64(),
        stats.received,
        stats.sent,
        stats.max_lateness.as_micros()
    );
    Ok(())
}

/// Where an emulated adapter meets its host: a pty at a path, or a TCP listener.
fn adapter_host(port: &PortSpec, bus: &FrameLinkSpec) -> anyhow::Result<AdapterHost> {
    match port {
        #[cfg(unix)]
        PortSpec::Device(path) => {
            let pair =
                PtyPair::open(&PtyOptions::default()).context("creating the pseudo-terminal")?;
            let slave_path = pair.slave_path.clone();
            // The master keeps its own slave descriptor; clients open the path.
            drop(pair.slave);
            let symlink = PtySymlink::create(path, &slave_path).map_err(|e| match e {
                LinkError::PathInUse { .. } => usage(format!("--bus {bus}: {e}")),
                e => anyhow::Error::new(e),
            })?;
            Ok(AdapterHost::Pty {
                master: pair.master,
                _symlink: symlink,
            })
        }
        #[cfg(not(unix))]
        PortSpec::Device(_) => Err(crate::exit::NotAvailable(format!(
            "--bus {bus}: this system has no pseudo-terminals; serve the adapter over TCP \
             with --bus {kind}:socket://127.0.0.1:PORT",
            kind = bus.candump_iface()
        ))
        .into()),
        PortSpec::Com(_) => Err(usage(format!(
            "--bus {bus}: a simulator presents its adapter on a pty path \
             ({kind}:/tmp/robobus-{kind}) or on TCP ({kind}:socket://127.0.0.1:PORT), not on a \
             COM port",
            kind = bus.candump_iface()
        ))),
        PortSpec::Tcp { host, port: tcp } => {
            let ip: std::net::IpAddr = host.parse().map_err(|_| {
                usage(format!(
                    "--bus {bus}: the simulator listens on an IP address of this machine \
                     (socket://127.0.0.1:PORT), not {host:?}"
                ))
            })?;
            let server = TcpServer::bind(std::net::SocketAddr::new(ip, *tcp), 115_200)
                .with_context(|| format!("listening on {host}:{tcp}"))?;
            Ok(AdapterHost::Tcp(server))
        }
    }
}

/// The byte stream an emulated adapter serves its host on.
enum AdapterHost {
    /// A pty master and the symlink clients open.
    #[cfg(unix)]
    Pty {
        /// The pty master.
        master: robobus_link::PtyLink,
        /// Removed when dropped (if it still points to this pty).
        _symlink: PtySymlink,
    },
    /// A TCP listener serving one client at a time.
    Tcp(TcpServer),
}

/// Serves the joints of `bus` behind the emulated `adapter` on `port` until Ctrl-C.
fn serve_adapter(
    args: &Args,
    bus: WhjBus,
    mut adapter: Box<dyn AdapterModel>,
    port: &PortSpec,
    wire_faults: Option<robobus_link::FaultConfig>,
    device: Vec<robobus_sim::faults::DeviceFault>,
    hands: &[Hand],
) -> anyhow::Result<()> {
    let (sim, handle) = WhjSimLink::with_faults(bus, FaultSchedule::new(device));
    let mut link: Box<dyn FrameLink + Send> = Box::new(sim);
    if let Some(faults) = wire_faults {
        link = Box::new(FaultyFrameLink::new(link, faults));
    }
    if let Some(path) = &args.capture {
        link = Box::new(capture_frame_link(
            link,
            path,
            args.bus.candump_iface(),
            Overwrite::No,
        )?);
    }
    let mut host = adapter_host(port, &args.bus)?;
    // Over TCP, the address with the port chosen (port 0 picks a free one).
    let (shown, address) = match &host {
        AdapterHost::Tcp(server) => {
            let (given, chosen) = (port.to_string(), server.port_spec().to_string());
            (
                args.bus.describe().replace(&given, &chosen),
                args.bus.to_string().replace(&given, &chosen),
            )
        }
        #[cfg(unix)]
        AdapterHost::Pty { .. } => (args.bus.describe(), args.bus.to_string()),
    };
    let token = crate::interrupt::stop_token();
    let stop = token.flag();
    let ids: Vec<String> = args.joints.0.iter().map(u8::to_string).collect();
    let announce = || {
        eprintln!(
            "robobus sim whj: serving {} joint(s) [{}] ({}) on {shown} (--bus {address}); \
             Ctrl-C to stop",
            ids.len(),
            ids.join(","),
            args.model,
        );
    };
    let t0 = std::time::Instant::now();
    let observe = |bus: &mut WhjBus| {
        let t = t0.elapsed().as_secs_f64();
        for h in hands {
            if let Some(j) = bus.joint_mut(h.id) {
                j.set_hand(Some(h.angle(t)));
            }
        }
    };
    let served = match &mut host {
        #[cfg(unix)]
        AdapterHost::Pty { master, .. } => adapter::run(
            &mut *adapter,
            master,
            &mut *link,
            &handle,
            stop,
            announce,
            observe,
        ),
        AdapterHost::Tcp(server) => adapter::run(
            &mut *adapter,
            server,
            &mut *link,
            &handle,
            stop,
            announce,
            observe,
        ),
    };
    let stats = served.context("serving the emulated adapter")?;
    // The symlink goes with the pty, after serving.
    drop(host);
    eprintln!(
        "robobus sim whj: stopped after {:.3} s: {} bytes in, {} bytes out, {} frames to the \
         joints, {} frames from them",
        t0.elapsed().as_secs_f64(),
        stats.host_bytes_in,
        stats.host_bytes_out,
        stats.frames_to_bus,
        stats.frames_from_bus
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joints_parse() {
        assert_eq!(parse_joints("1-7"), Ok(JointIds((1..=7).collect())));
        assert_eq!(parse_joints("3,1,2-3,9"), Ok(JointIds(vec![1, 2, 3, 9])));
        assert!(parse_joints("0-3").unwrap_err().contains("1..=30"));
        assert!(parse_joints("31").unwrap_err().contains("31"));
        assert!(parse_joints("5-2").unwrap_err().contains("5-2"));
        assert!(parse_joints("x").is_err());
        assert!(parse_joints("").is_err());
    }

    #[test]
    fn a_weak_drive_names_a_simulated_joint_and_a_current_up_to_the_peak() {
        let ids = [1, 2];
        let m = WhjModel::Whj30;
        assert_eq!(parse_weak_drive("2:0.3", &ids, m).unwrap(), (2, 0.3));
        for (text, why) in [
            ("3:0.3", "no simulated joint has this ID"),
            ("2", "two fields"),
            ("x:1", "the ID is not a number"),
            ("2:-1", "AMPS out of range 0..="),
            ("2:NaN", "AMPS out of range 0..="),
            ("2:1000", "AMPS out of range 0..="),
        ] {
            let e = parse_weak_drive(text, &ids, m).unwrap_err().to_string();
            assert!(e.contains(&format!("--weak-drive {text}: {why}")), "{e}");
        }
    }
}
