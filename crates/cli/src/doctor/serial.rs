//! Doctor's serial port checks: the ports come from the library's listing
//! ([`robobus::ops::ports`], the same as `robobus ports` on every OS), each with the
//! adapter robobus recognises and what it is for, its access (Unix: the device node and
//! its permissions) and its latency timer (Linux: read from sysfs and fixable; Windows and
//! macOS: the OS's own advice).

use std::path::{Path, PathBuf};

use robobus::ops::ports::{self, AdapterRole, Os, PortInfo, PortKind, PortList};

use super::{Finding, Status, finding};

/// The ports to check without `--port`: every USB port the OS lists, and one finding
/// naming the other ports it lists (on-board UARTs, Bluetooth) or saying none was found.
pub(super) fn listed(
    listing: &Result<PortList, robobus::ops::OpError>,
) -> (Vec<PathBuf>, Vec<Finding>) {
    let list = match listing {
        Ok(list) => list,
        Err(e) => {
            return (
                Vec::new(),
                vec![finding(
                    "serial",
                    "ports",
                    Status::Warn,
                    format!("the OS's port listing failed: {e}"),
                    Some("name the port with --port".into()),
                )],
            );
        }
    };
    let usb: Vec<PathBuf> = list
        .ports
        .iter()
        .filter(|p| p.kind == PortKind::Usb)
        .map(|p| PathBuf::from(&p.port))
        .collect();
    let others: Vec<&str> = list
        .ports
        .iter()
        .filter(|p| p.kind != PortKind::Usb)
        .map(|p| p.port.as_str())
        .collect();
    let mut findings = Vec::new();
    if usb.is_empty() {
        findings.push(finding(
            "serial",
            "ports",
            Status::Skip,
            format!(
                "no USB serial port found; {}",
                ports::where_ports_are(list.os)
            ),
            None,
        ));
    }
    if !others.is_empty() {
        findings.push(finding(
            "serial",
            "other ports",
            Status::Skip,
            format!(
                "not USB, not checked (name one with --port): {}",
                others.join(", ")
            ),
            None,
        ));
    }
    (usb, findings)
}

/// What the OS's listing says of `path` (matched by name, or by the device a symlink
/// such as `/dev/serial/by-id/...` points to).
pub(super) fn info_of<'a>(list: Option<&'a PortList>, path: &Path) -> Option<&'a PortInfo> {
    let list = list?;
    let resolved = std::fs::canonicalize(path).ok();
    let name = path.to_string_lossy();
    let bare = name.strip_prefix(r"\\.\").unwrap_or(&name);
    list.ports.iter().find(|p| {
        p.port.eq_ignore_ascii_case(bare)
            || resolved.as_deref().is_some_and(|r| r == Path::new(&p.port))
    })
}

/// The adapter finding: what the OS knows of the port and what robobus makes of it; for a
/// CAN FD adapter, the `--bus` that drives WHJ joints through it.
pub(super) fn adapter_finding(subject: &str, info: Option<&PortInfo>) -> Finding {
    let Some(info) = info else {
        return finding(
            subject,
            "adapter",
            Status::Skip,
            "not in the OS's port listing (a pseudo-terminal, or a port the OS cannot \
             describe)",
            None,
        );
    };
    let ids = match (info.vid, info.pid) {
        (Some(v), Some(p)) => format!("USB {v:04x}:{p:04x}"),
        _ => format!("{} port", info.kind.name()),
    };
    let strings: Vec<&str> = [&info.manufacturer, &info.product]
        .into_iter()
        .filter_map(Option::as_deref)
        .collect();
    let mut facts = ids;
    if !strings.is_empty() {
        facts = format!("{facts} ({})", strings.join(", "));
    }
    if let Some(serial) = &info.serial_number {
        facts = format!("{facts}, serial {serial}");
    }
    let detail = match (&info.adapter, &info.use_for) {
        (Some(name), Some(use_for)) => format!("{name}, {facts}: {use_for}"),
        _ if info.kind == PortKind::Usb => format!(
            "{facts}: not an adapter robobus knows; a USB-serial (UART) adapter is a wCK \
             bus: --port {subject}"
        ),
        _ => facts,
    };
    finding(subject, "adapter", Status::Ok, detail, None)
}

/// For a CAN FD adapter (slcan, fdcanusb): how WHJ joints are reached through it.
pub(super) fn can_fd_finding(subject: &str, info: Option<&PortInfo>) -> Option<Finding> {
    let adapter = info.and_then(|i| {
        ports::identify(
            i.vid?,
            i.pid?,
            i.manufacturer.as_deref(),
            i.product.as_deref(),
        )
    })?;
    let bus = match adapter.role {
        AdapterRole::WckBus => return None,
        AdapterRole::Slcan => format!("slcan:{subject}"),
        AdapterRole::Fdcanusb => format!("fdcanusb:{subject}"),
    };
    Some(finding(
        subject,
        "can fd",
        Status::Ok,
        format!(
            "{}: WHJ joints through it with --bus {bus} (the adapter is set to the joints' \
             1 / 5 Mbit/s); check them: robobus doctor --whj-bus {bus}",
            adapter.name
        ),
        None,
    ))
}

/// The latency timer on Windows and macOS, where robobus cannot read it: the OS's advice
/// for an FTDI adapter, nothing to say for the others.
#[cfg_attr(target_os = "linux", allow(dead_code))] // Linux reads sysfs; tested here too
pub(super) fn latency_elsewhere(os: Os, subject: &str, info: Option<&PortInfo>) -> Finding {
    match info.and_then(|i| i.latency_advice.clone()) {
        Some(advice) => finding(
            subject,
            "latency timer",
            Status::Warn,
            "an FTDI adapter: short replies wait up to its latency timer (16 ms unless set) \
             in the adapter",
            Some(advice),
        ),
        None => finding(
            subject,
            "latency timer",
            Status::Skip,
            format!(
                "no latency timer to set on {} (not an FTDI adapter)",
                os.name()
            ),
            None,
        ),
    }
}

/// Checks a serial port: what the OS knows of it and what it is for, whether it is there
/// and usable, its latency timer.
pub(super) fn check_serial(path: &Path, info: Option<&PortInfo>, fix: bool) -> Vec<Finding> {
    let subject = path.display().to_string();
    let mut out = access(path, &subject, info);
    if out
        .iter()
        .any(|f| f.check == "exists" && f.status == Status::Fail)
    {
        return out;
    }
    out.push(adapter_finding(&subject, info));
    out.extend(can_fd_finding(&subject, info));
    #[cfg(target_os = "linux")]
    out.push(check_latency(path, &subject, fix));
    #[cfg(not(target_os = "linux"))]
    {
        let _ = fix;
        out.push(latency_elsewhere(Os::current(), &subject, info));
    }
    out
}

/// Unix: the device node exists, is a character device, and is readable and writable.
#[cfg(unix)]
fn access(path: &Path, subject: &str, _info: Option<&PortInfo>) -> Vec<Finding> {
    use std::os::unix::fs::{FileTypeExt as _, MetadataExt as _};
    let mut out = Vec::new();
    let meta = match std::fs::metadata(path) {
        Ok(m) => m,
        Err(e) => {
            out.push(finding(
                subject,
                "exists",
                Status::Fail,
                format!("cannot stat: {e}"),
                Some(format!(
                    "check the cable and the adapter; `robobus ports` lists the serial ports \
                     the OS knows ({}); `robobus sim wck` prints a simulated port's path",
                    ports::where_ports_are(Os::current())
                )),
            ));
            return out;
        }
    };
    if meta.file_type().is_char_device() {
        out.push(finding(
            subject,
            "exists",
            Status::Ok,
            "character device",
            None,
        ));
    } else {
        out.push(finding(
            subject,
            "exists",
            Status::Warn,
            "exists but is not a character device (not a serial port)",
            Some(if cfg!(target_os = "macos") {
                "pass the device node, e.g. /dev/cu.usbserial-A10K".into()
            } else {
                "pass the device node, e.g. /dev/ttyUSB0".into()
            }),
        ));
    }
    let access = nix::unistd::access(
        path,
        nix::unistd::AccessFlags::R_OK | nix::unistd::AccessFlags::W_OK,
    );
    let group = group_name(meta.gid()).unwrap_or_else(|| meta.gid().to_string());
    match access {
        Ok(()) => out.push(finding(
            subject,
            "permissions",
            Status::Ok,
            format!("readable and writable (group {group})"),
            None,
        )),
        Err(e) => out.push(finding(
            subject,
            "permissions",
            Status::Fail,
            format!(
                "no read/write access ({e}); mode {:o}, group {group}",
                meta.mode() & 0o777
            ),
            Some(format!(
                "sudo usermod -aG {group} \"$USER\", then log out and in again"
            )),
        )),
    }
    out
}

/// Windows: the port is one the OS lists. Whether it opens is only known by opening it,
/// which doctor does not do, so a port the listing lacks is a warning (wine, for one,
/// maps COM ports to Linux devices without listing them).
#[cfg(not(unix))]
fn access(_path: &Path, subject: &str, info: Option<&PortInfo>) -> Vec<Finding> {
    vec![if info.is_some() {
        finding(subject, "exists", Status::Ok, "listed by the OS", None)
    } else {
        finding(
            subject,
            "exists",
            Status::Warn,
            "not among the ports the OS lists (doctor does not open it to find out more)",
            Some(format!(
                "check the cable and the driver; `robobus ports` lists the ports ({})",
                ports::where_ports_are(Os::current())
            )),
        )
    }]
}

/// The name of group `gid` from /etc/group.
#[cfg(unix)]
fn group_name(gid: u32) -> Option<String> {
    let text = std::fs::read_to_string("/etc/group").ok()?;
    text.lines().find_map(|l| {
        let mut f = l.split(':');
        let name = f.next()?;
        let _pw = f.next()?;
        (f.next()?.parse::<u32>().ok()? == gid).then(|| name.to_owned())
    })
}

/// Linux: the USB-serial latency timer read from sysfs, set with `--fix`.
#[cfg(target_os = "linux")]
fn check_latency(path: &Path, subject: &str, fix: bool) -> Finding {
    let tty = std::fs::canonicalize(path)
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "ttyUSB0".into());
    let manual_fix = format!(
        "robobus doctor --port {subject} --fix (as root), or `echo 1 | sudo tee \
         /sys/bus/usb-serial/devices/{tty}/latency_timer`; to keep it, a udev rule: {}",
        ports::FTDI_UDEV_RULE
    );
    match robobus_link::usb_latency_timer(path) {
        None => finding(
            subject,
            "latency timer",
            Status::Skip,
            "no USB-serial latency timer (not an FTDI-style adapter)",
            None,
        ),
        Some(1) => finding(subject, "latency timer", Status::Ok, "1 ms", None),
        Some(ms) if fix => match robobus_link::set_usb_latency_timer(path, 1) {
            Ok(()) => finding(
                subject,
                "latency timer",
                Status::Ok,
                format!("was {ms} ms, set to 1 ms (until the adapter is replugged)"),
                None,
            ),
            Err(e) => finding(
                subject,
                "latency timer",
                Status::Warn,
                format!("{ms} ms; setting it to 1 ms failed: {e}"),
                Some(manual_fix),
            ),
        },
        Some(ms) => finding(
            subject,
            "latency timer",
            Status::Warn,
            format!(
                "{ms} ms: each reply can wait up to {ms} ms in the adapter, capping the poll \
                 rate"
            ),
            Some(manual_fix),
        ),
    }
}
