//! `robobus sim whj`: simulated WHJ joints on a virtual CAN FD bus, served until
//! interrupted (Ctrl-C / SIGTERM).
//!
//! `--bus udp` joins python-can's `udp_multicast` bus (group 239.74.163.2, port 43113) on
//! the loopback interface; `--bus udp:GROUP:PORT` picks another group; any other value is
//! a `SocketCAN` interface (`vcan0`, `can0`; Linux only).

use std::net::Ipv4Addr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use robobus_link::udp::{UdpBus, UdpBusConfig};
use robobus_link::{FaultyFrameLink, FrameLink};
use robobus_sim::faults::{DeviceFaultKind, FaultSchedule};
use robobus_sim::whj::{JointConfig, WhjBus, WhjModel, serve_with};

use crate::exit::usage;
use crate::sim_wck::{LinkFaultArgs, device_faults};

/// What `robobus sim whj --help` adds after the options.
const AFTER_LONG_HELP: &str = "\
Readiness: the line \"serving ...\" appears on stderr once the simulator takes frames;
nothing a client sends from then on is missed.

Faults: --drop / --corrupt / --duplicate / --truncate / --delay / --disconnect-after act
on every frame (both directions) through the link layer's seeded fault injector: the same
--fault-seed and the same traffic give the same faults. --fault-error, --fault-silent and
--fault-power-cycle act on one joint at a time, SECONDS after serving starts (repeat them
for more).";

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
    /// The bus: `udp` (python-can `udp_multicast`, 239.74.163.2:43113), `udp:GROUP:PORT`, or
    /// a `SocketCAN` interface such as `vcan0`.
    #[arg(long, default_value = "udp", value_parser = parse_bus)]
    bus: BusSpec,
    /// Seed of the simulated measurement noise (same seed, same noise).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Standard deviation of the measured-current noise in mA (0 = exact values; the
    /// usage demo shows a few mA at standstill).
    #[arg(long, default_value_t = 5.0)]
    current_noise_ma: f64,
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

/// Parsed `--bus`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum BusSpec {
    /// python-can UDP multicast bus.
    Udp {
        /// Multicast group.
        group: Ipv4Addr,
        /// Port.
        port: u16,
    },
    /// A `SocketCAN` interface.
    SocketCan(String),
}

pub(crate) fn parse_joints(s: &str) -> Result<JointIds, String> {
    let mut ids = Vec::new();
    let id = |t: &str| -> Result<u8, String> {
        let v: u8 = t
            .trim()
            .parse()
            .map_err(|_| format!("joint ID {t:?} is not a number (allowed: 1..=30)"))?;
        if (1..=30).contains(&v) {
            Ok(v)
        } else {
            Err(format!("joint ID {v} out of range (allowed: 1..=30)"))
        }
    };
    for part in s.split(',').filter(|p| !p.trim().is_empty()) {
        if let Some((a, b)) = part.split_once('-') {
            let (a, b) = (id(a)?, id(b)?);
            if a > b {
                return Err(format!(
                    "joint range {a}-{b} is empty (write the lower ID first)"
                ));
            }
            ids.extend(a..=b);
        } else {
            ids.push(id(part)?);
        }
    }
    ids.sort_unstable();
    ids.dedup();
    if ids.is_empty() {
        return Err("no joint IDs given (example: 1-7)".into());
    }
    Ok(JointIds(ids))
}

pub(crate) fn parse_bus(s: &str) -> Result<BusSpec, String> {
    if s == "udp" {
        let d = UdpBusConfig::default();
        return Ok(BusSpec::Udp {
            group: d.group,
            port: d.port,
        });
    }
    if let Some(rest) = s.strip_prefix("udp:") {
        let (group, port) = rest.rsplit_once(':').ok_or_else(|| {
            format!("bus {s:?}: expected udp:GROUP:PORT, e.g. udp:239.74.163.2:43113")
        })?;
        let group: Ipv4Addr = group
            .parse()
            .map_err(|_| format!("bus {s:?}: {group:?} is not an IPv4 address"))?;
        if !group.is_multicast() {
            return Err(format!(
                "bus {s:?}: {group} is not a multicast group (allowed: 224.0.0.0/4)"
            ));
        }
        let port: u16 = port.parse().map_err(|_| {
            format!("bus {s:?}: port {port:?} is not a number (allowed: 1..=65535)")
        })?;
        if port == 0 {
            return Err(format!("bus {s:?}: port 0 (allowed: 1..=65535)"));
        }
        return Ok(BusSpec::Udp { group, port });
    }
    if s.is_empty() || s.len() > 15 || s.contains(['/', ' ', ':']) {
        return Err(format!(
            "bus {s:?}: expected udp, udp:GROUP:PORT, or a SocketCAN interface name such as vcan0"
        ));
    }
    Ok(BusSpec::SocketCan(s.to_owned()))
}

fn open_link(spec: &BusSpec) -> anyhow::Result<Box<dyn FrameLink>> {
    match spec {
        BusSpec::Udp { group, port } => {
            let cfg = UdpBusConfig {
                group: *group,
                port: *port,
                ..UdpBusConfig::default()
            };
            Ok(Box::new(UdpBus::open(&cfg).with_context(|| {
                format!("joining the UDP bus {group}:{port}")
            })?))
        }
        #[cfg(target_os = "linux")]
        BusSpec::SocketCan(iface) => Ok(Box::new(
            robobus_link::socketcan::SocketCanLink::open(iface)
                .with_context(|| format!("opening SocketCAN interface {iface}"))?,
        )),
        #[cfg(not(target_os = "linux"))]
        BusSpec::SocketCan(iface) => {
            anyhow::bail!(
                "SocketCAN interface {iface}: SocketCAN exists on Linux only; use --bus udp"
            )
        }
    }
}

fn describe(spec: &BusSpec) -> String {
    match spec {
        BusSpec::Udp { group, port } => format!("udp_multicast {group}:{port}"),
        BusSpec::SocketCan(iface) => format!("SocketCAN {iface}"),
    }
}

/// Serves the simulated bus until interrupted.
pub(crate) fn run(args: &Args) -> anyhow::Result<()> {
    if !args.current_noise_ma.is_finite() || args.current_noise_ma < 0.0 {
        return Err(usage(format!(
            "--current-noise-ma {} out of range (allowed: 0 or more)",
            args.current_noise_ma
        )));
    }
    if !args.initial_deg.is_finite() || args.initial_deg.abs() > 214_748.0 {
        return Err(usage(format!(
            "--initial-deg {} out of range (allowed: -214748..=214748)",
            args.initial_deg
        )));
    }
    let wire_faults =
        args.faults
            .config(args.seed, ("drop", args.drop), ("corrupt", args.corrupt))?;
    let device = device_faults(
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
    )?;
    let configs = args.joints.0.iter().map(|&id| {
        let mut cfg = JointConfig::new(id, args.model);
        cfg.current_noise_ma = args.current_noise_ma;
        cfg.boot.wait_for_iap_flag = !args.no_iap;
        cfg.processing_delay = Duration::from_micros(args.processing_delay_us);
        cfg.initial_position_deg = args.initial_deg;
        cfg
    });
    let mut bus = WhjBus::with_configs(configs, args.seed);
    let mut link = open_link(&args.bus)?;
    if let Some(faults) = wire_faults {
        link = Box::new(FaultyFrameLink::new(link, faults));
    }

    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C / SIGTERM handler")?;

    let ids: Vec<String> = args.joints.0.iter().map(u8::to_string).collect();
    let announce = || {
        eprintln!(
            "robobus sim whj: serving {} joint(s) [{}] ({}) on {}; Ctrl-C to stop",
            ids.len(),
            ids.join(","),
            args.model,
            describe(&args.bus)
        );
    };
    let stats = serve_with(
        &mut bus,
        &mut *link,
        &stop,
        FaultSchedule::new(device),
        announce,
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
    fn bus_parses() {
        assert_eq!(
            parse_bus("udp"),
            Ok(BusSpec::Udp {
                group: Ipv4Addr::new(239, 74, 163, 2),
                port: 43113
            })
        );
        assert_eq!(
            parse_bus("udp:239.1.2.3:5000"),
            Ok(BusSpec::Udp {
                group: Ipv4Addr::new(239, 1, 2, 3),
                port: 5000
            })
        );
        assert!(
            parse_bus("udp:10.0.0.1:5000")
                .unwrap_err()
                .contains("multicast")
        );
        assert!(parse_bus("udp:239.1.2.3").is_err());
        assert!(parse_bus("udp:239.1.2.3:0").is_err());
        assert_eq!(parse_bus("vcan0"), Ok(BusSpec::SocketCan("vcan0".into())));
        assert!(parse_bus("a/b").is_err());
    }
}
