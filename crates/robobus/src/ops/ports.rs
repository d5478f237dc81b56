//! The serial ports of this machine as its OS knows them, with what robobus makes of each.
//!
//! [`list`] asks the OS through `serialport::available_ports()`: on Windows the COM ports
//! of its device manager (`COM3`), on macOS the `IOKit` serial devices (the call-out
//! `/dev/cu.*`; their dial-in `/dev/tty.*` twins are left out), on Linux a scan of
//! `/sys/class/tty` (robobus is built without libudev): `/dev/ttyUSB*`, `/dev/ttyACM*`,
//! on-board UARTs. A pseudo-terminal (a simulator's `--link` path) is not a device the OS
//! lists, so it never appears here.
//!
//! Each port gets its kind (USB, PCI, Bluetooth, unknown), its USB vendor and product IDs,
//! manufacturer, product and serial number where the OS reports them, and the adapter
//! robobus recognises in [`ADAPTERS`] (one table, kept as data here) with what it is for:
//! a wCK bus (`--port PORT`) or a CAN FD adapter (`--bus slcan:PORT`,
//! `--bus fdcanusb:PORT`). An FTDI adapter holds short replies back for its latency timer
//! (16 ms unless set); [`latency_advice`] says how to set it to 1 ms on this OS, and on
//! Linux the value is read from sysfs first.
//!
//! Bounded: at most [`MAX_PORTS`] ports, each text cut to [`MAX_TEXT`] characters.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::OpError;

/// The most ports listed (the rest are counted, not shown).
pub const MAX_PORTS: usize = 256;

/// The longest manufacturer / product / serial number / port name kept, characters (a USB
/// string descriptor holds at most 126).
pub const MAX_TEXT: usize = 128;

/// How the port is attached, as the OS reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum PortKind {
    /// A USB device (USB-serial adapter, USB CDC device).
    Usb,
    /// A PCI card or a chipset UART.
    Pci,
    /// A Bluetooth serial link.
    Bluetooth,
    /// Anything else (an on-board UART, a port the OS cannot place).
    Unknown,
}

impl PortKind {
    /// The lowercase name (`usb`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Usb => "usb",
            Self::Pci => "pci",
            Self::Bluetooth => "bluetooth",
            Self::Unknown => "unknown",
        }
    }
}

/// What a recognised adapter is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum AdapterRole {
    /// A USB-serial (UART) adapter: a wCK bus, `--port PORT`.
    WckBus,
    /// A CAN FD adapter speaking slcan with the CAN FD extension: `--bus slcan:PORT`.
    Slcan,
    /// mjbots' fdcanusb: `--bus fdcanusb:PORT`.
    Fdcanusb,
}

/// How an adapter is recognised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdapterMatch {
    /// By its USB vendor and product IDs.
    Usb(u16, u16),
    /// By its USB manufacturer and product strings (exact, ignoring ASCII case), whatever
    /// its IDs.
    Strings(&'static str, &'static str),
}

/// One adapter robobus recognises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Adapter {
    /// How it is recognised.
    pub matches: AdapterMatch,
    /// Its name as shown (`FTDI FT232R`).
    pub name: &'static str,
    /// What it is for.
    pub role: AdapterRole,
    /// Whether the chip holds short replies for a latency timer (FTDI).
    pub latency_timer: bool,
}

const fn usb(
    vid: u16,
    pid: u16,
    name: &'static str,
    role: AdapterRole,
    latency_timer: bool,
) -> Adapter {
    Adapter {
        matches: AdapterMatch::Usb(vid, pid),
        name,
        role,
        latency_timer,
    }
}

/// The adapters robobus recognises, first match wins.
///
/// Sources of the IDs:
/// - FTDI (`0403`): Linux `drivers/usb/serial/ftdi_sio_ids.h`: `FTDI_8U232AM_PID 0x6001`
///   (FT232R, FT232BM), `FTDI_8U2232C_PID 0x6010` (FT2232), `FTDI_4232H_PID 0x6011`,
///   `FTDI_232H_PID 0x6014`, `FTDI_FTX_PID 0x6015` ("FT-X series (FT201X, FT230X,
///   FT231X, etc)"). The ROBOTIS U2D2 is an FT232H (its e-Manual: "the Virtual COM Port
///   Driver to detect the FTDI devices such as the U2D2"); it reports the FT232H's IDs.
/// - WCH (`1a86`): Linux `drivers/usb/serial/ch341.c` `id_table`: `0x7523` (CH340),
///   `0x5523` (CH341 in UART mode).
/// - Silicon Labs (`10c4`): Linux `drivers/usb/serial/cp210x.c`: `0xEA60` ("Silicon Labs
///   factory default": CP2102, CP2104, ...), `0xEA70` (CP2105).
/// - `CANable` 2.0 with its slcan firmware: `normaldotcom/canable2-fw` `src/usbd_desc.c`:
///   `USBD_VID 0x16d0`, `USBD_PID 0x117e`, manufacturer "Openlight Labs", product
///   `CANable2 ...`.
/// - mjbots fdcanusb: `mjbots/fdcanusb` `fw/stm32g4_async_usb_cdc.cc`: `idVendor 0x1209`,
///   `idProduct 0x2323`, manufacturer "mjbots", product "fdcanusb"; its udev rule
///   (`70-fdcanusb.rules`) matches those two strings, which older firmware also reports.
pub const ADAPTERS: &[Adapter] = &[
    usb(0x0403, 0x6001, "FTDI FT232R", AdapterRole::WckBus, true),
    usb(0x0403, 0x6010, "FTDI FT2232", AdapterRole::WckBus, true),
    usb(0x0403, 0x6011, "FTDI FT4232H", AdapterRole::WckBus, true),
    usb(
        0x0403,
        0x6014,
        "FTDI FT232H (as in the ROBOTIS U2D2)",
        AdapterRole::WckBus,
        true,
    ),
    usb(
        0x0403,
        0x6015,
        "FTDI FT-X (FT231X, FT230X)",
        AdapterRole::WckBus,
        true,
    ),
    usb(0x1a86, 0x7523, "WCH CH340", AdapterRole::WckBus, false),
    usb(0x1a86, 0x5523, "WCH CH341", AdapterRole::WckBus, false),
    usb(
        0x10c4,
        0xea60,
        "Silicon Labs CP210x",
        AdapterRole::WckBus,
        false,
    ),
    usb(
        0x10c4,
        0xea70,
        "Silicon Labs CP2105",
        AdapterRole::WckBus,
        false,
    ),
    usb(
        0x16d0,
        0x117e,
        "CANable 2.0 (slcan firmware)",
        AdapterRole::Slcan,
        false,
    ),
    usb(
        0x1209,
        0x2323,
        "mjbots fdcanusb",
        AdapterRole::Fdcanusb,
        false,
    ),
    Adapter {
        matches: AdapterMatch::Strings("mjbots", "fdcanusb"),
        name: "mjbots fdcanusb",
        role: AdapterRole::Fdcanusb,
        latency_timer: false,
    },
];

/// The adapter of [`ADAPTERS`] a USB port with these IDs and strings is, if any.
pub fn identify(
    vid: u16,
    pid: u16,
    manufacturer: Option<&str>,
    product: Option<&str>,
) -> Option<&'static Adapter> {
    ADAPTERS.iter().find(|a| match a.matches {
        AdapterMatch::Usb(v, p) => v == vid && p == pid,
        AdapterMatch::Strings(m, p) => {
            manufacturer.is_some_and(|x| x.trim().eq_ignore_ascii_case(m))
                && product.is_some_and(|x| x.trim().eq_ignore_ascii_case(p))
        }
    })
}

/// What the adapter is for, with the option that names this port
/// (`wCK bus: --port /dev/ttyUSB0`, `CAN FD adapter: --bus slcan:COM8`).
pub fn use_for(role: AdapterRole, port: &str) -> String {
    match role {
        AdapterRole::WckBus => format!("wCK bus: --port {port}"),
        AdapterRole::Slcan => format!("CAN FD adapter: --bus slcan:{port}"),
        AdapterRole::Fdcanusb => format!("CAN FD adapter: --bus fdcanusb:{port}"),
    }
}

/// The operating systems whose advice differs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Os {
    /// Linux.
    Linux,
    /// Windows.
    Windows,
    /// macOS.
    Macos,
    /// Another system.
    Other,
}

impl Os {
    /// The system this program runs on.
    pub const fn current() -> Self {
        if cfg!(target_os = "linux") {
            Self::Linux
        } else if cfg!(windows) {
            Self::Windows
        } else if cfg!(target_os = "macos") {
            Self::Macos
        } else {
            Self::Other
        }
    }

    /// Its name (`linux`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Linux => "linux",
            Self::Windows => "windows",
            Self::Macos => "macos",
            Self::Other => "other",
        }
    }
}

/// The udev rule that sets every FTDI adapter's latency timer to 1 ms when it is plugged
/// in (Linux).
pub const FTDI_UDEV_RULE: &str = "ACTION==\"add\", SUBSYSTEM==\"usb-serial\", \
                                  DRIVER==\"ftdi_sio\", ATTR{latency_timer}=\"1\"";

/// How to get an FTDI adapter's latency timer to 1 ms on `os`, given the value read
/// (`timer_ms`, Linux only); `None` when nothing is to be done (not an FTDI chip, or the
/// timer already 1 ms).
pub fn latency_advice(
    os: Os,
    port: &str,
    adapter: Option<&Adapter>,
    timer_ms: Option<u32>,
) -> Option<String> {
    if !adapter.is_some_and(|a| a.latency_timer) || timer_ms == Some(1) {
        return None;
    }
    Some(match os {
        Os::Linux => {
            let tty = port.rsplit('/').next().unwrap_or(port);
            let now = timer_ms.map_or_else(
                || "the latency timer (16 ms unless set)".to_owned(),
                |ms| format!("latency timer {ms} ms"),
            );
            format!(
                "{now}: each reply can wait that long in the adapter; set 1 ms: `echo 1 | sudo \
                 tee /sys/bus/usb-serial/devices/{tty}/latency_timer` (or `robobus doctor \
                 --port {port} --fix` as root); to keep it, a udev rule in \
                 /etc/udev/rules.d/99-ftdi-latency.rules: {FTDI_UDEV_RULE}"
            )
        }
        Os::Windows => format!(
            "FTDI latency timer (16 ms unless set): Device Manager > Ports (COM & LPT) > \
             {port} > Properties > Port Settings > Advanced > Latency Timer (msec): 1"
        ),
        Os::Macos => "FTDI latency timer (16 ms unless set): Apple's built-in FTDI driver \
                      has no setting for it; FTDI's own VCP driver takes `LatencyTimer` = 1 \
                      from its configuration (FTDI's macOS installation guide). Until then \
                      replies can come up to 16 ms late: raise --reply-margin, or use a \
                      CH340 / CP210x adapter (no latency timer)"
            .to_owned(),
        Os::Other => "FTDI latency timer (16 ms unless set): set it to 1 ms with the driver's own \
             setting"
            .to_owned(),
    })
}

/// One serial port of this machine.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub struct PortInfo {
    /// The port as options take it: a path (`/dev/ttyUSB0`, `/dev/cu.usbserial-A10K`) or
    /// a COM name (`COM3`).
    #[serde(rename = "id")]
    pub port: String,
    /// How it is attached.
    pub kind: PortKind,
    /// USB vendor ID.
    pub vid: Option<u16>,
    /// USB product ID.
    pub pid: Option<u16>,
    /// USB manufacturer string.
    pub manufacturer: Option<String>,
    /// USB product string.
    pub product: Option<String>,
    /// USB serial number.
    pub serial_number: Option<String>,
    /// The adapter robobus recognises (`FTDI FT232R`), from [`ADAPTERS`].
    pub adapter: Option<String>,
    /// What that adapter is for, with the option naming this port
    /// (`CAN FD adapter: --bus slcan:COM8`).
    pub use_for: Option<String>,
    /// The adapter's latency timer, ms, as just read (Linux sysfs; null where it cannot
    /// be read: another OS, or a chip without one).
    pub latency_timer_ms: Option<u32>,
    /// How to set an FTDI adapter's latency timer to 1 ms on this OS (null: nothing to do).
    pub latency_advice: Option<String>,
}

/// The ports of this machine, and how many more there were past [`MAX_PORTS`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub struct PortList {
    /// The system asked.
    pub os: Os,
    /// The ports, sorted by name (COM ports by number).
    pub ports: Vec<PortInfo>,
    /// Ports left out past [`MAX_PORTS`].
    pub left_out: usize,
}

/// What the OS said of one port, before robobus looks at it (the input of [`describe`]).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RawPort {
    /// The port's name.
    pub name: String,
    /// How it is attached.
    pub kind: Option<PortKind>,
    /// USB vendor ID.
    pub vid: Option<u16>,
    /// USB product ID.
    pub pid: Option<u16>,
    /// USB manufacturer.
    pub manufacturer: Option<String>,
    /// USB product.
    pub product: Option<String>,
    /// USB serial number.
    pub serial_number: Option<String>,
}

fn cut(text: &str) -> String {
    text.chars().take(MAX_TEXT).collect()
}

fn cut_opt(text: Option<&str>) -> Option<String> {
    text.map(str::trim).filter(|t| !t.is_empty()).map(cut)
}

/// The ports of this machine as the OS lists them, each described ([`describe`]); on
/// Linux each FTDI adapter's latency timer is read from sysfs.
///
/// # Errors
/// [`OpError::NotAvailable`] where the OS has no serial port listing (Linux without
/// `/sys/class/tty`), [`OpError::File`] (kind `link`) when the OS's listing fails.
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub fn list() -> Result<PortList, OpError> {
    let os = Os::current();
    if os == Os::Linux && !std::path::Path::new("/sys/class/tty").is_dir() {
        // serialport's sysfs scan panics without it.
        return Err(OpError::NotAvailable(
            "listing serial ports: /sys/class/tty is not there (is /sys mounted?); name the \
             port instead (--port /dev/ttyUSB0)"
                .into(),
        ));
    }
    let found = serialport::available_ports().map_err(|e| OpError::File {
        path: "serial ports".into(),
        reason: format!("the OS's serial port listing failed: {e}"),
        kind: super::ErrorKind::Link,
    })?;
    let raw = found.into_iter().map(|p| {
        let mut r = RawPort {
            name: p.port_name,
            ..RawPort::default()
        };
        r.kind = Some(match p.port_type {
            serialport::SerialPortType::UsbPort(u) => {
                r.vid = Some(u.vid);
                r.pid = Some(u.pid);
                r.manufacturer = u.manufacturer;
                r.product = u.product;
                r.serial_number = u.serial_number;
                PortKind::Usb
            }
            serialport::SerialPortType::PciPort => PortKind::Pci,
            serialport::SerialPortType::BluetoothPort => PortKind::Bluetooth,
            serialport::SerialPortType::Unknown => PortKind::Unknown,
        });
        r
    });
    Ok(describe(os, raw, &read_latency_timer))
}

#[cfg(target_os = "linux")]
fn read_latency_timer(port: &str) -> Option<u32> {
    robobus_link::usb_latency_timer(port)
}

#[cfg(not(target_os = "linux"))]
fn read_latency_timer(_port: &str) -> Option<u32> {
    None
}

/// The sort key of a port name: COM ports by number (`COM3` before `COM12`), then paths.
fn sort_key(name: &str) -> (u8, u32, String) {
    let bare = name.strip_prefix(r"\\.\").unwrap_or(name);
    let com = bare
        .get(..3)
        .filter(|p| p.eq_ignore_ascii_case("COM"))
        .and_then(|_| bare.get(3..))
        .and_then(|n| n.parse::<u32>().ok());
    match com {
        Some(n) => (0, n, String::new()),
        None => (1, 0, name.to_owned()),
    }
}

/// Describes what the OS listed on `os`: sorted, bounded, each USB port identified from
/// [`ADAPTERS`] with its use and latency advice. `timer` reads an FTDI adapter's latency
/// timer by port name, on Linux only (elsewhere the OS does not show it). On macOS a
/// `/dev/tty.*` dial-in device whose `/dev/cu.*` twin is listed is left out.
pub fn describe(
    os: Os,
    raw: impl IntoIterator<Item = RawPort>,
    timer: &dyn Fn(&str) -> Option<u32>,
) -> PortList {
    let mut raw: Vec<RawPort> = raw.into_iter().take(4 * MAX_PORTS).collect();
    if os == Os::Macos {
        let callout: std::collections::HashSet<String> = raw
            .iter()
            .filter_map(|p| p.name.strip_prefix("/dev/cu.").map(str::to_owned))
            .collect();
        raw.retain(|p| {
            p.name
                .strip_prefix("/dev/tty.")
                .is_none_or(|rest| !callout.contains(rest))
        });
    }
    raw.sort_by_key(|p| sort_key(&p.name));
    raw.dedup_by(|a, b| a.name == b.name);
    let left_out = raw.len().saturating_sub(MAX_PORTS);
    raw.truncate(MAX_PORTS);
    let ports = raw
        .into_iter()
        .map(|p| {
            let port = cut(&p.name);
            let manufacturer = cut_opt(p.manufacturer.as_deref());
            let product = cut_opt(p.product.as_deref());
            let adapter = match (p.vid, p.pid) {
                (Some(v), Some(i)) => identify(v, i, manufacturer.as_deref(), product.as_deref()),
                _ => None,
            };
            let latency_timer_ms = adapter
                .filter(|a| a.latency_timer && os == Os::Linux)
                .and_then(|_| timer(&port));
            PortInfo {
                kind: p.kind.unwrap_or(PortKind::Unknown),
                vid: p.vid,
                pid: p.pid,
                serial_number: cut_opt(p.serial_number.as_deref()),
                adapter: adapter.map(|a| a.name.to_owned()),
                use_for: adapter.map(|a| use_for(a.role, &port)),
                latency_timer_ms,
                latency_advice: latency_advice(os, &port, adapter, latency_timer_ms),
                manufacturer,
                product,
                port,
            }
        })
        .collect();
    PortList {
        os,
        ports,
        left_out,
    }
}

/// Where the OS puts serial ports and how they are named, for a message when none is found.
pub const fn where_ports_are(os: Os) -> &'static str {
    match os {
        Os::Linux => {
            "USB-serial adapters are /dev/ttyUSB*, USB CDC devices (CANable, fdcanusb) \
             /dev/ttyACM*; `ls -l /dev/serial/by-id/` shows them by name"
        }
        Os::Windows => {
            "ports are COM1, COM2, ...: Device Manager > Ports (COM & LPT) shows them; an \
             adapter without a driver is under Other devices"
        }
        Os::Macos => "ports are /dev/cu.* (`ls /dev/cu.*`); use the cu device, not /dev/tty.*",
        Os::Other => "see the system's documentation for its serial devices",
    }
}

#[cfg(test)]
#[path = "ports_tests.rs"]
mod tests;
