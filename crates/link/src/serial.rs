//! Serial ports (USB-serial adapters, on-board UARTs) through the `serialport` crate, on
//! Linux, macOS and Windows, and the Linux USB-serial `latency_timer`.
//!
//! The port is opened 8N1 without flow control, exclusively (on Unix TIOCEXCL and an
//! exclusive `flock`; Windows opens a COM port for one program only), so a second robobus
//! program gets [`LinkError::Busy`]. Reads return as soon as any byte is there ("low
//! latency" at this level) and end at their deadline: on Linux `serialport` waits in
//! `ppoll` (nanoseconds); where the wait counts whole milliseconds (macOS `poll`, Windows'
//! COM timeouts) the remainder under a millisecond is polled, so a read never ends early.
//! Windows may end a COM timeout late by up to a tick of its system timer.
//!
//! On FTDI adapters the chip itself holds short replies back until its latency timer runs
//! out (16 ms by default): on Linux [`usb_latency_timer`] reads it from sysfs and
//! [`set_usb_latency_timer`] lowers it; on other systems it is the driver's setting
//! ([`LATENCY_TIMER_ADVICE`] says where), and these answer `None` and
//! [`LinkError::NotAvailable`].

use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::{ClearBuffer, DataBits, FlowControl, Parity, SerialPort, StopBits};

use crate::byte::{ByteLink, LinkError};

/// How long a write may wait for the port to take the bytes.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

/// The `serialport` type of this system's ports.
#[cfg(unix)]
type NativePort = serialport::TTYPort;
/// The `serialport` type of this system's ports.
#[cfg(windows)]
type NativePort = serialport::COMPort;

/// A serial port opened by path (`/dev/ttyUSB0`, `/dev/cu.usbserial-A1`, `COM3`,
/// `\\.\COM12`).
#[derive(Debug)]
pub struct SerialLink {
    port: NativePort,
    path: PathBuf,
    baud: u32,
}

impl SerialLink {
    /// Opens `path` at `baud`, 8N1, no flow control, exclusive.
    ///
    /// Errors name the path: [`LinkError::NoSuchDevice`], [`LinkError::Busy`],
    /// [`LinkError::PermissionDenied`], [`LinkError::UnsupportedBaud`] (the port runs at
    /// another rate than `baud`, more than 2 % off), or [`LinkError::Io`].
    pub fn open(path: impl AsRef<Path>, baud: u32) -> Result<Self, LinkError> {
        let path = path.as_ref().to_path_buf();
        #[cfg(unix)]
        match std::fs::metadata(&path) {
            Ok(_) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                return Err(LinkError::NoSuchDevice { path });
            }
            Err(e) if e.kind() == io::ErrorKind::PermissionDenied => {
                return Err(LinkError::PermissionDenied { path });
            }
            Err(e) => return Err(LinkError::io(format!("opening {}", path.display()), e)),
        }
        if baud == 0 {
            return Err(LinkError::UnsupportedBaud {
                baud,
                context: path.display().to_string(),
            });
        }
        let path_str = path.to_string_lossy().into_owned();
        let builder = serialport::new(path_str, baud)
            .data_bits(DataBits::Eight)
            .parity(Parity::None)
            .stop_bits(StopBits::One)
            .flow_control(FlowControl::None)
            .timeout(Duration::from_millis(1));
        #[cfg(unix)]
        let builder = builder.exclusive(true);
        let port = builder
            .open_native()
            .map_err(|e| map_open_error(&path, &e))?;
        let link = Self { port, path, baud };
        link.check_baud(baud)?;
        Ok(link)
    }

    /// Refuses a rate the port did not take: a UART whose clock cannot make it runs at
    /// another rate without an error (an 8250 with a 115200 bit/s base clock asked for
    /// 921600), and every reply would then be lost for a reason no one could see.
    fn check_baud(&self, baud: u32) -> Result<(), LinkError> {
        match self.port.baud_rate() {
            Ok(actual) if !baud_close_enough(baud, actual) => Err(LinkError::UnsupportedBaud {
                baud,
                context: format!(
                    "{} (it runs at {actual} bit/s instead)",
                    self.path.display()
                ),
            }),
            _ => Ok(()),
        }
    }

    /// The path the port was opened with.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// This port's USB-serial latency timer in milliseconds, if it has one (Linux, FTDI
    /// and similar adapters; `None` on other systems, where the driver holds it).
    pub fn latency_timer(&self) -> Option<u32> {
        usb_latency_timer(&self.path)
    }

    fn io_err(&self, what: &str, e: io::Error) -> LinkError {
        LinkError::io(format!("{what} {}", self.path.display()), e)
    }
}

fn map_open_error(path: &Path, e: &serialport::Error) -> LinkError {
    let path = path.to_path_buf();
    match e.kind() {
        // serialport reports a held TIOCEXCL / flock as NoDevice ("Unable to acquire
        // exclusive lock", or EBUSY); the path exists (checked before), so it is busy.
        #[cfg(unix)]
        serialport::ErrorKind::NoDevice => LinkError::Busy { path },
        // Windows: NoDevice is "not found" and "access denied" alike, and a COM port
        // another program holds answers "access denied": busy if the system lists it.
        #[cfg(windows)]
        serialport::ErrorKind::NoDevice => {
            if listed_port(&path) {
                LinkError::Busy { path }
            } else {
                LinkError::NoSuchDevice { path }
            }
        }
        serialport::ErrorKind::Io(io::ErrorKind::NotFound) => LinkError::NoSuchDevice { path },
        serialport::ErrorKind::Io(io::ErrorKind::PermissionDenied) => {
            LinkError::PermissionDenied { path }
        }
        serialport::ErrorKind::Io(kind) => LinkError::io(
            format!("opening serial port {}", path.display()),
            io::Error::new(kind, e.description.clone()),
        ),
        serialport::ErrorKind::InvalidInput | serialport::ErrorKind::Unknown => LinkError::io(
            format!(
                "opening serial port {} (is it a serial device?)",
                path.display()
            ),
            io::Error::other(e.description.clone()),
        ),
    }
}

/// Whether the system lists the port at `path` (`COM3`, `\\.\COM3`), by name.
#[cfg(windows)]
fn listed_port(path: &Path) -> bool {
    let name = path.to_string_lossy();
    let name = name.strip_prefix(r"\\.\").unwrap_or(&name);
    serialport::available_ports()
        .is_ok_and(|ports| ports.iter().any(|p| p.port_name.eq_ignore_ascii_case(name)))
}

/// Whether a read's error means the device went away (unplugged).
fn device_gone(e: &io::Error) -> bool {
    #[cfg(unix)]
    {
        e.raw_os_error() == Some(nix::errno::Errno::EIO as i32)
    }
    #[cfg(windows)]
    {
        /// `ERROR_BAD_COMMAND` and `ERROR_DEVICE_REMOVED` (winerror.h): what a read of a
        /// USB-serial port answers once the adapter is unplugged.
        const GONE: [i32; 2] = [22, 1617];
        e.raw_os_error().is_some_and(|code| GONE.contains(&code))
    }
}

impl ByteLink for SerialLink {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        // Reads shrink the port's timeout to their deadline; writes get their own.
        self.port
            .set_timeout(WRITE_TIMEOUT)
            .map_err(|e| self.io_err("setting write timeout on", io::Error::other(e)))?;
        let mut written = 0;
        while let Some(rest) = bytes.get(written..).filter(|r| !r.is_empty()) {
            match self.port.write(rest) {
                Ok(0) => {
                    return Err(LinkError::WriteTimeout {
                        written,
                        total: bytes.len(),
                    });
                }
                Ok(n) => written += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == io::ErrorKind::TimedOut => {
                    return Err(LinkError::WriteTimeout {
                        written,
                        total: bytes.len(),
                    });
                }
                Err(e) => return Err(self.io_err("writing to", e)),
            }
        }
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        loop {
            let remaining = deadline.saturating_duration_since(Instant::now());
            self.port
                .set_timeout(remaining)
                .map_err(|e| self.io_err("setting read timeout on", io::Error::other(e)))?;
            match self.port.read(buf) {
                Ok(0) => {
                    return Err(LinkError::Closed {
                        context: format!("{}: end of file", self.path.display()),
                    });
                }
                Ok(n) => return Ok(n),
                // A timeout in whole milliseconds ends before a deadline between them:
                // the rest is polled (a zero timeout returns at once).
                Err(e) if e.kind() == io::ErrorKind::TimedOut && Instant::now() < deadline => {}
                Err(e) if e.kind() == io::ErrorKind::TimedOut => {
                    return Err(LinkError::Timeout {
                        received: 0,
                        expected: buf.len(),
                    });
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if device_gone(&e) => {
                    return Err(LinkError::Closed {
                        context: format!("{}: device gone ({e})", self.path.display()),
                    });
                }
                Err(e) => return Err(self.io_err("reading from", e)),
            }
        }
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        self.port
            .clear(ClearBuffer::Input)
            .map_err(|e| self.io_err("flushing input of", io::Error::other(e)))
    }

    fn set_baud(&mut self, baud: u32) -> Result<(), LinkError> {
        self.port
            .set_baud_rate(baud)
            .map_err(|e| LinkError::UnsupportedBaud {
                baud,
                context: format!("{} ({e})", self.path.display()),
            })?;
        self.check_baud(baud)?;
        self.baud = baud;
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(self.baud)
    }
}

/// Whether a port running at `actual` bit/s talks to one at `asked`: within 2 % (what
/// asynchronous serial tolerates; USB adapters round a rate to their divider, e.g. an FTDI
/// chip makes 921600 as 923077).
fn baud_close_enough(asked: u32, actual: u32) -> bool {
    u64::from(asked.abs_diff(actual)) * 50 <= u64::from(asked)
}

/// The sysfs directory where Linux lists USB-serial ports.
pub const USB_SERIAL_SYSFS: &str = "/sys/bus/usb-serial/devices";

/// Where this system keeps an FTDI-style adapter's latency timer, and how to lower it.
#[cfg(target_os = "linux")]
pub const LATENCY_TIMER_ADVICE: &str = "Linux: /sys/bus/usb-serial/devices/<tty>/latency_timer \
     (robobus sets it with root or a udev rule: ATTR{latency_timer}=\"1\")";
/// Where this system keeps an FTDI-style adapter's latency timer, and how to lower it.
#[cfg(windows)]
pub const LATENCY_TIMER_ADVICE: &str = "Windows: Device Manager, the port's Properties, Port \
     Settings, Advanced..., Latency Timer (msec): set 1";
/// Where this system keeps an FTDI-style adapter's latency timer, and how to lower it.
#[cfg(target_os = "macos")]
pub const LATENCY_TIMER_ADVICE: &str = "macOS: the driver holds it (FTDI's VCP driver reads \
     LatencyTimer from its ConfigData; Apple's own driver has no setting)";
/// Where this system keeps an FTDI-style adapter's latency timer, and how to lower it.
#[cfg(not(any(target_os = "linux", target_os = "macos", windows)))]
pub const LATENCY_TIMER_ADVICE: &str = "the serial driver's settings";

/// The latency timer (ms) of the USB-serial adapter behind `path` (Linux, FTDI-style
/// drivers), or `None` if the device is not a USB-serial port with a latency timer, and
/// always on other systems (their drivers hold it: [`LATENCY_TIMER_ADVICE`]). Symlinks
/// such as `/dev/serial/by-id/...` are resolved first.
pub fn usb_latency_timer(path: impl AsRef<Path>) -> Option<u32> {
    if cfg!(target_os = "linux") {
        latency_timer_at(Path::new(USB_SERIAL_SYSFS), path.as_ref())
    } else {
        None
    }
}

/// Sets the latency timer (1..=255 ms) of the USB-serial adapter behind `path`. Needs write
/// access to sysfs (root, or a udev rule). Linux only: elsewhere
/// [`LinkError::NotAvailable`], naming the driver setting to use instead.
pub fn set_usb_latency_timer(path: impl AsRef<Path>, ms: u32) -> Result<(), LinkError> {
    if cfg!(target_os = "linux") {
        set_latency_timer_at(Path::new(USB_SERIAL_SYSFS), path.as_ref(), ms)
    } else {
        Err(LinkError::NotAvailable {
            what: format!(
                "setting the USB latency timer of {} from robobus",
                path.as_ref().display()
            ),
            instead: LATENCY_TIMER_ADVICE.into(),
        })
    }
}

/// The sysfs `latency_timer` file for a device path under a given sysfs directory.
fn latency_file(sysfs: &Path, path: &Path) -> Option<PathBuf> {
    let resolved = std::fs::canonicalize(path).ok()?;
    let tty = resolved.file_name()?;
    Some(sysfs.join(tty).join("latency_timer"))
}

/// [`usb_latency_timer`] with the sysfs directory given (for tests).
pub fn latency_timer_at(sysfs: &Path, path: &Path) -> Option<u32> {
    let text = std::fs::read_to_string(latency_file(sysfs, path)?).ok()?;
    text.trim().parse().ok()
}

/// [`set_usb_latency_timer`] with the sysfs directory given (for tests).
pub fn set_latency_timer_at(sysfs: &Path, path: &Path, ms: u32) -> Result<(), LinkError> {
    if !(1..=255).contains(&ms) {
        return Err(LinkError::io(
            format!("setting the latency timer of {}", path.display()),
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("{ms} ms is out of range (allowed: 1..=255)"),
            ),
        ));
    }
    let file = latency_file(sysfs, path).ok_or_else(|| LinkError::NoSuchDevice {
        path: path.to_path_buf(),
    })?;
    std::fs::write(&file, format!("{ms}\n")).map_err(|e| {
        LinkError::io(
            format!(
                "writing {} (is {} a USB-serial adapter? writing needs root or a udev rule)",
                file.display(),
                path.display()
            ),
            e,
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rate_the_port_changed_is_refused_a_divider_rounding_is_not() {
        assert!(baud_close_enough(921_600, 921_600));
        assert!(baud_close_enough(921_600, 923_077)); // FTDI's divider
        assert!(baud_close_enough(115_200, 117_504)); // +2.0 %
        assert!(!baud_close_enough(115_200, 117_600)); // +2.1 %
        assert!(!baud_close_enough(921_600, 115_200)); // an 8250's base clock
        assert!(!baud_close_enough(4_800, 0));
    }

    #[cfg(unix)]
    #[test]
    fn latency_timer_resolves_symlinks_and_reads_sysfs() {
        let dir = tempfile::tempdir().unwrap();
        let sysfs = dir.path().join("sys");
        std::fs::create_dir_all(sysfs.join("ttyUSB7")).unwrap();
        std::fs::write(sysfs.join("ttyUSB7/latency_timer"), "16\n").unwrap();
        let dev = dir.path().join("ttyUSB7");
        std::fs::write(&dev, "").unwrap();
        let by_id = dir.path().join("usb-FTDI_FT232R-if00-port0");
        std::os::unix::fs::symlink(&dev, &by_id).unwrap();

        assert_eq!(latency_timer_at(&sysfs, &by_id), Some(16));
        set_latency_timer_at(&sysfs, &by_id, 1).unwrap();
        assert_eq!(latency_timer_at(&sysfs, &dev), Some(1));
        assert!(set_latency_timer_at(&sysfs, &dev, 0).is_err());
        assert!(set_latency_timer_at(&sysfs, &dev, 256).is_err());

        let other = dir.path().join("ttyS0");
        std::fs::write(&other, "").unwrap();
        assert_eq!(latency_timer_at(&sysfs, &other), None);
        assert_eq!(latency_timer_at(&sysfs, &dir.path().join("missing")), None);
    }

    #[cfg(not(target_os = "linux"))]
    #[test]
    fn the_latency_timer_is_the_drivers_elsewhere() {
        assert_eq!(usb_latency_timer("COM3"), None);
        let err = set_usb_latency_timer("COM3", 1).unwrap_err();
        assert!(
            matches!(&err, LinkError::NotAvailable { instead, .. } if instead == LATENCY_TIMER_ADVICE),
            "{err}"
        );
    }

    #[cfg(unix)]
    #[test]
    fn missing_device_is_a_clear_error() {
        let err = SerialLink::open("/dev/robobus-no-such-tty", 115_200).unwrap_err();
        assert!(
            matches!(&err, LinkError::NoSuchDevice { path } if path == Path::new("/dev/robobus-no-such-tty"))
        );
        let text = err.to_string();
        assert!(
            text.contains("/dev/robobus-no-such-tty") && text.contains("plugged in"),
            "{text}"
        );
    }

    #[cfg(windows)]
    #[test]
    fn a_com_port_the_system_does_not_have_is_no_such_device() {
        let err = SerialLink::open(r"\\.\COM250", 115_200).unwrap_err();
        assert!(
            matches!(&err, LinkError::NoSuchDevice { path } if path == Path::new(r"\\.\COM250")),
            "{err}"
        );
    }
}
