//! `robobus doctor`: checks what breaks real setups, each finding with a concrete fix.
//!
//! The checks are independent functions returning [`Finding`]s, grouped by what they look
//! at: serial ports ([`serial`]: the library's port listing, the same as `robobus ports`
//! on every OS, with each adapter's use and the OS's latency advice), SocketCAN interfaces
//! ([`check_can`], Linux) and the UDP bus ([`check_udp`]); none of them opens a port or
//! sends anything. The device checks in
//! [`probe`] (silent devices, joints waiting in their bootloader, shared IDs, firmware
//! gates) talk to the devices through the client, and run only when asked
//! (`--wck-port`, `--whj-bus`).
//!
//! Exit code 0 when nothing failed (warnings allowed), 5 when a check failed.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::json;

use crate::Global;
use crate::exit::{ProblemsFound, usage};

mod probe;
mod serial;

/// Options of `robobus doctor`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Without --port / --can, every USB serial port the OS lists (as `robobus ports` shows
them: COM ports on Windows, /dev/cu.* on macOS, /dev/ttyUSB* and /dev/ttyACM* on Linux)
and every CAN interface found (Linux) is checked, and the UDP bus always is. A recognised
CAN FD adapter is named with the --bus that uses it (slcan:PORT, fdcanusb:PORT). Nothing
is opened or sent, except to the devices named by --wck-port / --whj-bus: those are
probed (a wCK scan; WHJ status queries, the IAP release of a joint waiting in its
bootloader, identity reads).
Exit code 0 when no check failed (warnings allowed), 5 when one did; --can on a system
without SocketCAN is exit code 4.")]
pub(crate) struct Args {
    /// Serial port(s) to check (repeatable).
    #[arg(long, value_name = "PATH")]
    port: Vec<PathBuf>,
    /// SocketCAN interface(s) to check (repeatable), e.g. can0, vcan0.
    #[arg(long, value_name = "IFACE")]
    can: Vec<String>,
    /// Apply the fixes robobus can apply itself: set USB-serial latency timers to 1 ms
    /// (needs write access to sysfs, usually root).
    #[arg(long)]
    fix: bool,
    /// Probe the wCK servos on this serial port: scan IDs 0..=30 at --wck-baud, report
    /// the servos found and IDs shared by two modules.
    #[arg(long, value_name = "PATH")]
    wck_port: Option<String>,
    /// Baud rate for --wck-port.
    #[arg(long, value_name = "BAUD", default_value = "115200", value_parser = crate::wck::parse_baud)]
    wck_baud: robobus_wck::BaudRate,
    /// Extra reply wait for --wck-port in ms (default 10 plus the adapter's latency timer;
    /// raise it for a simulator on a loaded machine).
    #[arg(long, value_name = "MS", value_parser = crate::wck::parse_margin)]
    reply_margin: Option<std::time::Duration>,
    /// Probe the WHJ joints on this bus (udp, udp:GROUP:PORT, a SocketCAN interface, or a
    /// serial-line CAN FD adapter: slcan:PORT, fdcanusb:PORT):
    /// silent joints, joints waiting in their bootloader (released), IDs shared by two
    /// joints, firmware lacking a feature robobus uses.
    #[arg(long, value_name = "BUS")]
    whj_bus: Option<String>,
    /// Joint IDs for --whj-bus: a range `1-7`, a list `1,2,5`, or both.
    #[arg(long, value_name = "IDS", default_value = "1-7", value_parser = crate::sim_whj::parse_joints)]
    joints: crate::sim_whj::JointIds,
}

/// Outcome of one check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Status {
    /// Fine.
    Ok,
    /// Works, but not as well as it could.
    Warn,
    /// Broken: robobus will not work this way.
    Fail,
    /// Not applicable here.
    Skip,
}

impl Status {
    fn label(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::Warn => "warn",
            Self::Fail => "FAIL",
            Self::Skip => "skip",
        }
    }
}

/// One finding: what was checked, the outcome, the facts, and the fix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Finding {
    /// What the check looked at (`/dev/ttyUSB0`, `can0`, `udp bus`).
    pub(crate) subject: String,
    /// The check's name.
    pub(crate) check: &'static str,
    /// Outcome.
    pub(crate) status: Status,
    /// What was found.
    pub(crate) detail: String,
    /// How to fix it (for warn / fail).
    pub(crate) fix: Option<String>,
}

fn finding(
    subject: &str,
    check: &'static str,
    status: Status,
    detail: impl Into<String>,
    fix: Option<String>,
) -> Finding {
    Finding {
        subject: subject.to_owned(),
        check,
        status,
        detail: detail.into(),
        fix,
    }
}

/// The widest SUBJECT / CHECK column of the table; longer values run over.
const MAX_COLUMN: usize = 40;

/// The longest network interface name, bytes (`IFNAMSIZ` 16 with its NUL).
pub(crate) const MAX_IFACE_BYTES: usize = 15;

/// The longest path, bytes (`PATH_MAX` 4096 with its NUL).
pub(crate) const MAX_PATH_BYTES: usize = 4095;

/// `value` for an error message: the first 32 characters and the length if it is longer.
fn shown(value: &str) -> String {
    if value.chars().count() <= 32 {
        format!("`{value}`")
    } else {
        let head: String = value.chars().take(32).collect();
        format!("`{head}...` ({} bytes)", value.len())
    }
}

/// A SocketCAN interface name: 1..=15 bytes, no `/`, no whitespace, not `.` or `..`.
pub(crate) fn check_iface(option: &str, name: &str) -> anyhow::Result<()> {
    if name.is_empty() || name.len() > MAX_IFACE_BYTES {
        return Err(usage(format!(
            "{option} {}: an interface name has 1..={MAX_IFACE_BYTES} bytes",
            shown(name)
        )));
    }
    if name == "." || name == ".." || name.chars().any(|c| c == '/' || c.is_whitespace()) {
        return Err(usage(format!(
            "{option} {}: an interface name has no `/` or whitespace and is not `.` or `..`",
            shown(name)
        )));
    }
    Ok(())
}

/// A device path: 1..=4095 bytes.
pub(crate) fn check_path(option: &str, path: &std::ffi::OsStr) -> anyhow::Result<()> {
    let len = path.len();
    if len == 0 || len > MAX_PATH_BYTES {
        return Err(usage(format!(
            "{option} {}: a path has 1..={MAX_PATH_BYTES} bytes",
            shown(&path.to_string_lossy())
        )));
    }
    Ok(())
}

/// Every name the user typed, checked before anything is looked at.
fn check_args(args: &Args) -> anyhow::Result<()> {
    for p in &args.port {
        check_path("--port", p.as_os_str())?;
    }
    for c in &args.can {
        check_iface("--can", c)?;
    }
    if let Some(p) = &args.wck_port {
        check_path("--wck-port", std::ffi::OsStr::new(p))?;
    }
    if let Some(b) = &args.whj_bus {
        if let Some(port) = b
            .strip_prefix("slcan:")
            .or_else(|| b.strip_prefix("fdcanusb:"))
        {
            // A serial-line CAN FD adapter: its port is a path (or COM name).
            check_path("--whj-bus", std::ffi::OsStr::new(port))?;
        } else if b == "udp" || b.starts_with("udp:") {
            if b.len() > 64 {
                return Err(usage(format!(
                    "--whj-bus {}: a UDP bus is `udp` or `udp:GROUP:PORT` (at most 64 bytes)",
                    shown(b)
                )));
            }
        } else {
            check_iface("--whj-bus", b)?;
        }
    }
    Ok(())
}

/// Runs `robobus doctor`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    check_args(args)?;
    if !args.can.is_empty() && !cfg!(target_os = "linux") {
        return Err(anyhow::Error::new(robobus::ops::OpError::NotAvailable(
            "doctor --can checks a SocketCAN interface, which only Linux has; here a CAN FD \
             adapter is a serial-line one: `robobus ports` lists it, `robobus doctor --whj-bus \
             slcan:PORT` (or fdcanusb:PORT) probes the joints behind it"
                .into(),
        )));
    }
    let everything = args.port.is_empty() && args.can.is_empty();
    // The same listing as `robobus ports`, on every OS.
    let listing = robobus::ops::ports::list();
    let mut findings = Vec::new();
    let ports = if everything {
        let (ports, notes) = serial::listed(&listing);
        findings.extend(notes);
        ports
    } else {
        args.port.clone()
    };
    let cans = if everything {
        find_can_interfaces(Path::new(NET_DIR))
    } else {
        args.can.clone()
    };
    for p in &ports {
        let info = serial::info_of(listing.as_ref().ok(), p);
        findings.extend(serial::check_serial(p, info, args.fix));
    }
    findings.extend(check_can_kernel());
    for iface in &cans {
        findings.extend(check_can(Path::new(NET_DIR), iface));
    }
    findings.extend(check_udp(Path::new(NET_DIR)));
    if let Some(port) = &args.wck_port {
        findings.extend(probe_wck(port, args.wck_baud, args.reply_margin));
    }
    if let Some(bus) = &args.whj_bus {
        findings.extend(probe_adapter(bus));
        findings.extend(probe_whj(bus, &args.joints.0));
    }
    report(g, &findings)
}

fn probe_wck(
    port: &str,
    baud: robobus_wck::BaudRate,
    margin: Option<std::time::Duration>,
) -> Vec<Finding> {
    match robobus::wck::WckBus::open(port, baud) {
        Ok(mut bus) => {
            if let Some(m) = margin {
                bus.config_mut().margin = m;
            }
            probe::wck(&mut bus, port)
        }
        Err(e) => vec![finding(port, "open", Status::Fail, e.to_string(), None)],
    }
}

/// A serial-line CAN FD adapter named by `--whj-bus` (`slcan:PORT`, `fdcanusb:PORT`),
/// opened alone (set to the joints' rates, no frame sent) so that the findings say the
/// adapter itself answers, and which slcan version it is, before its joints are probed.
/// `None` for another bus, or when it does not open: the probe's open finding says why.
fn probe_adapter(bus: &str) -> Option<Finding> {
    use robobus_link::FrameLinkSpec as Spec;
    let detail = match bus.parse::<Spec>().ok()? {
        Spec::Slcan { port, baud } => {
            let name = port.to_string();
            let link = port
                .open(baud.unwrap_or(robobus_link::spec::SLCAN_DEFAULT_BAUD))
                .ok()?;
            let adapter = robobus_link::slcan::SlcanLink::open(
                link,
                &name,
                &robobus_link::slcan::SlcanConfig::default(),
            )
            .ok()?;
            format!(
                "slcan adapter on {name} answers (version {}), set to 1 / 5 Mbit/s",
                adapter.version()
            )
        }
        Spec::Fdcanusb { port } => {
            let name = port.to_string();
            let link = port.open(robobus_link::spec::FDCANUSB_BAUD).ok()?;
            robobus_link::fdcanusb::FdcanusbLink::open(
                link,
                &name,
                robobus_link::fdcanusb::FdcanusbConfig::default(),
            )
            .ok()?;
            format!("fdcanusb on {name} answers, set to 1 / 5 Mbit/s")
        }
        _ => return None,
    };
    Some(finding(bus, "adapter", Status::Ok, detail, None))
}

fn probe_whj(bus_name: &str, ids: &[u8]) -> Vec<Finding> {
    let opened = robobus::station::open_whj_with(
        bus_name,
        None,
        robobus::whj::JointBusConfig {
            connect_timeout: std::time::Duration::from_millis(500),
            ..robobus::whj::JointBusConfig::default()
        },
    );
    match opened {
        Ok(bus) => probe::whj(&bus, bus_name, ids),
        Err(e) => vec![finding(
            bus_name,
            "open",
            Status::Fail,
            format!("{e:#}"),
            None,
        )],
    }
}

fn report(g: Global, findings: &[Finding]) -> anyhow::Result<()> {
    let failed = findings.iter().filter(|f| f.status == Status::Fail).count();
    if g.json {
        let rows: Vec<_> = findings
            .iter()
            .map(|f| {
                json!({
                    "subject": f.subject,
                    "check": f.check,
                    "status": f.status.label().to_ascii_lowercase(),
                    "detail": f.detail,
                    "fix": f.fix,
                })
            })
            .collect();
        crate::output::print_json(&json!({"ok": failed == 0, "findings": rows}))?;
    } else {
        crate::output::print(&table(findings))?;
    }
    if failed > 0 {
        return Err(anyhow::Error::new(ProblemsFound(failed)));
    }
    Ok(())
}

/// The checklist as a text table; fixes on an indented line below their finding.
fn table(findings: &[Finding]) -> String {
    let w_subject = findings
        .iter()
        .map(|f| f.subject.chars().count())
        .max()
        .unwrap_or(7)
        .clamp(7, MAX_COLUMN);
    let w_check = findings
        .iter()
        .map(|f| f.check.len())
        .max()
        .unwrap_or(5)
        .clamp(5, MAX_COLUMN);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<4}  {:<w_subject$}  {:<w_check$}  DETAIL",
        "", "SUBJECT", "CHECK"
    );
    for f in findings {
        let _ = writeln!(
            s,
            "{:<4}  {:<w_subject$}  {:<w_check$}  {}",
            f.status.label(),
            f.subject,
            f.check,
            f.detail
        );
        if let Some(fix) = &f.fix {
            let _ = writeln!(s, "{:<4}  {:<w_subject$}  fix: {fix}", "", "");
        }
    }
    s
}

// ---------------------------------------------------------------- SocketCAN

const NET_DIR: &str = "/sys/class/net";
/// `ARPHRD_CAN`.
const ARPHRD_CAN: u32 = 280;
/// MTU of a CAN FD capable interface.
const CANFD_MTU: u32 = 72;

fn read_u32(path: &Path) -> Option<u32> {
    let t = std::fs::read_to_string(path).ok()?;
    let t = t.trim();
    match t.strip_prefix("0x") {
        Some(hex) => u32::from_str_radix(hex, 16).ok(),
        None => t.parse().ok(),
    }
}

fn find_can_interfaces(net_dir: &Path) -> Vec<String> {
    let mut out: Vec<String> = std::fs::read_dir(net_dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| read_u32(&e.path().join("type")) == Some(ARPHRD_CAN))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    out.sort();
    out
}

/// Whether this kernel has SocketCAN (Linux).
#[cfg(target_os = "linux")]
fn check_can_kernel() -> Vec<Finding> {
    vec![if robobus_link::socketcan::kernel_has_can() {
        finding(
            "socketcan",
            "kernel",
            Status::Ok,
            "AF_CAN sockets available",
            None,
        )
    } else {
        finding(
            "socketcan",
            "kernel",
            Status::Warn,
            "this kernel has no SocketCAN (socket(AF_CAN) fails); only the UDP bus works",
            Some(
                "sudo modprobe can can_raw vcan (if the modules exist); otherwise use \
                 --bus udp"
                    .into(),
            ),
        )
    }]
}

/// SocketCAN is Linux's: elsewhere, what reaches WHJ joints instead.
#[cfg(not(target_os = "linux"))]
fn check_can_kernel() -> Vec<Finding> {
    vec![finding(
        "socketcan",
        "kernel",
        Status::Skip,
        format!(
            "SocketCAN is Linux's; on {} WHJ joints are reached through a serial-line CAN FD \
             adapter (--bus slcan:PORT or fdcanusb:PORT; `robobus ports` names them) or the \
             UDP bus",
            robobus::ops::ports::Os::current().name()
        ),
        None,
    )]
}

/// The WHJ joints' bit timing as `ip link ... type can` arguments: 1 Mbit/s arbitration
/// with its sample point at 80 %, 5 Mbit/s data at 75 % (the vendor's usage demo).
pub(crate) const CAN_FD_TIMING: &str =
    "bitrate 1000000 sample-point 0.8 dbitrate 5000000 dsample-point 0.75 fd on";

/// Checks a SocketCAN interface under `net_dir`: exists, is CAN, is up, is FD-capable, and
/// (via `ip -details -json`) its bit rates and FD mode.
pub(crate) fn check_can(net_dir: &Path, iface: &str) -> Vec<Finding> {
    let dir = net_dir.join(iface);
    let is_virtual = iface.starts_with("vcan");
    let setup = if is_virtual {
        format!(
            "sudo modprobe vcan && sudo ip link add dev {iface} type vcan && sudo ip link set \
             {iface} mtu 72 up"
        )
    } else {
        format!(
            "sudo ip link set {iface} down && sudo ip link set {iface} type can {CAN_FD_TIMING} \
             && sudo ip link set {iface} up"
        )
    };
    if !dir.exists() {
        return vec![finding(
            iface,
            "exists",
            Status::Fail,
            "no such network interface",
            Some(if is_virtual {
                setup
            } else {
                format!(
                    "plug in the CAN FD adapter, check `ip link`, then: {setup}; or test with a \
                     virtual bus: sudo modprobe vcan && sudo ip link add dev vcan0 type vcan && \
                     sudo ip link set vcan0 mtu 72 up"
                )
            }),
        )];
    }
    let mut out = Vec::new();
    match read_u32(&dir.join("type")) {
        Some(ARPHRD_CAN) => out.push(finding(iface, "type", Status::Ok, "CAN interface", None)),
        other => {
            out.push(finding(
                iface,
                "type",
                Status::Fail,
                format!("not a CAN interface (link type {other:?}, CAN is 280)"),
                Some("name a CAN interface (`ip -details link show type can`)".into()),
            ));
            return out;
        }
    }
    let up = read_u32(&dir.join("flags")).is_some_and(|f| f & 1 != 0);
    out.push(if up {
        finding(iface, "up", Status::Ok, "interface is up", None)
    } else {
        finding(
            iface,
            "up",
            Status::Fail,
            "interface is down",
            Some(format!("sudo ip link set {iface} up")),
        )
    });
    match read_u32(&dir.join("mtu")) {
        Some(CANFD_MTU) => out.push(finding(
            iface,
            "fd mtu",
            Status::Ok,
            "MTU 72 (CAN FD)",
            None,
        )),
        Some(mtu) => out.push(finding(
            iface,
            "fd mtu",
            Status::Fail,
            format!("MTU {mtu}: not CAN FD (needs 72); WHJ joints talk CAN FD only"),
            Some(setup.clone()),
        )),
        None => out.push(finding(
            iface,
            "fd mtu",
            Status::Skip,
            "MTU unreadable",
            None,
        )),
    }
    if is_virtual {
        out.push(finding(
            iface,
            "bit rates",
            Status::Skip,
            "virtual interface: no bit timing",
            None,
        ));
    } else {
        out.push(check_bit_rates(iface, &setup));
    }
    out.push(check_controller(iface));
    out
}

/// The controller's state (Linux's netlink data; not on another OS).
#[cfg(not(target_os = "linux"))]
pub(crate) fn check_controller(iface: &str) -> Finding {
    finding(
        iface,
        "controller",
        Status::Skip,
        "a CAN controller's state is read from Linux's netlink",
        None,
    )
}

/// The controller's state, error counters and restarts, from the kernel's netlink data.
#[cfg(target_os = "linux")]
pub(crate) fn check_controller(iface: &str) -> Finding {
    match robobus_link::socketcan::health::read(iface) {
        Ok(h) => controller_finding(&h),
        Err(e) => finding(
            iface,
            "controller",
            Status::Skip,
            format!("cannot read its state: {e}"),
            None,
        ),
    }
}

/// Judges a CAN interface's health: error-active is fine, error-warning and -passive
/// warn, bus-off and stopped fail, and so does a controller running classic CAN (CAN FD
/// off: WHJ joints cannot hear it); the counters and the state changes so far are shown.
#[cfg(target_os = "linux")]
pub(crate) fn controller_finding(h: &robobus_link::socketcan::health::CanHealth) -> Finding {
    use robobus_link::socketcan::health::ControllerState as S;
    let Some(state) = h.state else {
        return finding(
            &h.iface,
            "controller",
            Status::Skip,
            format!(
                "{}: no controller state (a virtual interface has none)",
                h.kind.as_deref().unwrap_or("no link kind")
            ),
            None,
        );
    };
    let mut detail = state.name().to_owned();
    if let (Some(tx), Some(rx)) = (h.tx_errors, h.rx_errors) {
        let _ = write!(detail, ", error counters tx {tx} rx {rx}");
    }
    if let Some(s) = h.stats {
        let _ = write!(
            detail,
            "; so far {} error-warning, {} error-passive, {} bus-off, {} restarts, {} bus \
             errors",
            s.error_warning, s.error_passive, s.bus_off, s.restarts, s.bus_error
        );
    }
    if let Some(ms) = h.restart_ms {
        let _ = write!(
            detail,
            "; {}",
            if ms == 0 {
                "no automatic restart".to_owned()
            } else {
                format!("restarts {ms} ms after bus-off")
            }
        );
    }
    let status = match state {
        _ if h.classic() => Status::Fail,
        S::ErrorActive => Status::Ok,
        S::ErrorWarning | S::ErrorPassive | S::Sleeping | S::Unknown(_) => Status::Warn,
        S::BusOff | S::Stopped => Status::Fail,
    };
    if h.classic() {
        detail.push_str("; classic CAN (CAN FD off)");
    }
    finding(&h.iface, "controller", status, detail, h.advice())
}

/// Bit rates and FD mode from `ip -details -json link show IFACE`.
fn check_bit_rates(iface: &str, setup: &str) -> Finding {
    let Ok(o) = Command::new("ip")
        .args(["-details", "-json", "link", "show", iface])
        .output()
    else {
        return finding(
            iface,
            "bit rates",
            Status::Skip,
            "`ip` (iproute2) not found; cannot read the bit timing",
            Some("sudo apt-get install iproute2".into()),
        );
    };
    let parsed: Option<serde_json::Value> = serde_json::from_slice(&o.stdout).ok();
    let Some(data) = parsed
        .as_ref()
        .and_then(|v| v.get(0))
        .and_then(|v| v.pointer("/linkinfo/info_data"))
    else {
        return finding(
            iface,
            "bit rates",
            Status::Skip,
            "`ip -details -json` shows no CAN bit timing",
            None,
        );
    };
    bit_rate_finding(iface, data, setup)
}

/// Judges the `info_data` object of `ip -details -json link show` for a CAN interface.
pub(crate) fn bit_rate_finding(iface: &str, data: &serde_json::Value, setup: &str) -> Finding {
    let bitrate = data
        .pointer("/bittiming/bitrate")
        .and_then(serde_json::Value::as_u64);
    let dbitrate = data
        .pointer("/data_bittiming/bitrate")
        .and_then(serde_json::Value::as_u64);
    let fd = data
        .get("ctrlmode")
        .and_then(serde_json::Value::as_array)
        .is_some_and(|m| m.iter().any(|x| x.as_str() == Some("FD")));
    // `ip -json` prints sample points as strings ("0.800"); accept numbers too.
    let sample_point = |pointer: &str| {
        data.pointer(pointer).and_then(|v| {
            v.as_f64()
                .or_else(|| v.as_str().and_then(|s| s.trim().parse().ok()))
        })
    };
    let sp = sample_point("/bittiming/sample_point");
    let dsp = sample_point("/data_bittiming/sample_point");
    let detail = format!(
        "bitrate {}, dbitrate {}, fd {}",
        bitrate.map_or_else(|| "?".into(), |b| b.to_string()),
        dbitrate.map_or_else(|| "?".into(), |b| b.to_string()),
        if fd { "on" } else { "off" }
    );
    let points_off = [(sp, 0.8), (dsp, 0.75)]
        .iter()
        .any(|(got, want)| got.is_some_and(|g| (g - want).abs() > 0.0125));
    if bitrate == Some(1_000_000) && dbitrate == Some(5_000_000) && fd && points_off {
        let show = |v: Option<f64>| v.map_or_else(|| "?".into(), |v| format!("{v:.3}"));
        finding(
            iface,
            "bit rates",
            Status::Warn,
            format!(
                "{detail}, sample points {} / {}; the WHJ joints sample at 0.800 / 0.750",
                show(sp),
                show(dsp)
            ),
            Some(setup.to_owned()),
        )
    } else if bitrate == Some(1_000_000) && dbitrate == Some(5_000_000) && fd {
        finding(iface, "bit rates", Status::Ok, detail, None)
    } else {
        finding(
            iface,
            "bit rates",
            Status::Fail,
            format!("{detail}; WHJ joints need 1000000 / 5000000 with fd on"),
            Some(setup.to_owned()),
        )
    }
}

// ---------------------------------------------------------------- UDP bus

/// Checks what the UDP bus needs: loopback up; and, for python-can peers, a multicast
/// route on `lo`.
pub(crate) fn check_udp(net_dir: &Path) -> Vec<Finding> {
    let subject = "udp bus";
    if !cfg!(target_os = "linux") {
        return vec![finding(
            subject,
            "loopback",
            Status::Skip,
            format!(
                "not checked on {} (the checks read Linux's /sys/class/net and `ip`)",
                robobus::ops::ports::Os::current().name()
            ),
            None,
        )];
    }
    let mut out = Vec::new();
    let lo_up = read_u32(&net_dir.join("lo").join("flags")).is_some_and(|f| f & 1 != 0);
    out.push(if lo_up {
        finding(subject, "loopback", Status::Ok, "lo is up", None)
    } else {
        finding(
            subject,
            "loopback",
            Status::Fail,
            "the loopback interface is down; the UDP bus lives on it",
            Some("sudo ip link set lo up".into()),
        )
    });
    let group = robobus_link::udp::DEFAULT_GROUP.to_string();
    let route = Command::new("ip")
        .args(["route", "get", &group])
        .output()
        .ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned());
    out.push(match route {
        None => finding(
            subject,
            "multicast route",
            Status::Skip,
            "`ip` (iproute2) not found",
            None,
        ),
        Some(r)
            if r.split_whitespace()
                .collect::<Vec<_>>()
                .windows(2)
                .any(|w| w == ["dev", "lo"]) =>
        {
            finding(
                subject,
                "multicast route",
                Status::Ok,
                format!("{group} routes via lo (python-can peers can join)"),
                None,
            )
        }
        Some(r) => finding(
            subject,
            "multicast route",
            Status::Warn,
            format!(
                "{group} does not route via lo ({}); robobus endpoints do not need it, \
                 python-can peers do",
                r.split_whitespace().collect::<Vec<_>>().join(" ")
            ),
            Some(
                "in a private network namespace (unshare -n): ip link set lo up; ip route \
                 add 224.0.0.0/4 dev lo"
                    .into(),
            ),
        ),
    });
    out
}

#[cfg(test)]
mod tests;
