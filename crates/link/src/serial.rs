//! Serial ports (USB-serial adapters, on-board UARTs) through the `serialport` crate, and
//! the Linux USB-serial `latency_timer`.
//!
//! The port is opened 8N1 without flow control, exclusively (TIOCEXCL and an exclusive
//! `flock`, so a second robobus program gets [`LinkError::Busy`]). Reads return as soon as
//! any byte is there ("low latency" at this level). On FTDI adapters the chip itself holds
//! short replies back until its latency timer runs out (16 ms by default on Linux):
//! [`usb_latency_timer`] reads it and [`set_usb_latency_timer`] lowers it.

use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::{ClearBuffer, DataBits, FlowControl, Parity, SerialPort, StopBits};

use crate::byte::{ByteLink, LinkError};

/// How long a write may wait for the port to take the bytes.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

/// A serial port opened by path.
#[derive(Debug)]
pub struct SerialLink {
    port: serialport::TTYPort,
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
        let port = serialport::new(path_str, baud)
            .data_bits(DataBits::Eight)
            .parity(Parity::None)
            .stop_bits(StopBits::One)
            .flow_control(FlowControl::None)
            .timeout(Duration::from_millis(1))
            .exclusive(true)
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
    /// and similar adapters).
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
        serialport::ErrorKind::NoDevice => LinkError::Busy { path },
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
                Err(e) if e.kind() == io::ErrorKind::TimedOut => {
                    return Err(LinkError::Timeout {
                        received: 0,
                        expected: buf.len(),
                    });
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if e.raw_os_error() == Some(nix::errno::Errno::EIO as i32) => {
                    return Err(LinkError::Closed {
                        context: format!("{}: device gone (EIO)", self.path.display()),
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

/// The latency timer (ms) of the USB-serial adapter behind `path` (Linux, FTDI-style
/// drivers), or `None` if the device is not a USB-serial port with a latency timer.
/// Symlinks such as `/dev/serial/by-id/...` are resolved first.
pub fn usb_latency_timer(path: impl AsRef<Path>) -> Option<u32> {
    latency_timer_at(Path::new(USB_SERIAL_SYSFS), path.as_ref())
}

/// Sets the latency timer (1..=255 ms) of the USB-serial adapter behind `path`. Needs write
/// access to sysfs (root, or a udev rule).
pub fn set_usb_latency_timer(path: impl AsRef<Path>, ms: u32) -> Result<(), LinkError> {
    set_latency_timer_at(Path::new(USB_SERIAL_SYSFS), path.as_ref(), ms)
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
}
