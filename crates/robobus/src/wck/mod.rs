//! wCK servos (RoboBuilder): a [`WckBus`] owns the UART link, [`Servo`] handles borrow it.
//!
//! - Every command of the manual's appendix A-1 is a typed method on [`Servo`] (or, for
//!   the broadcast ones, on [`WckBus`]: [`WckBus::sync_move`], [`WckBus::break_all`],
//!   [`WckBus::scan`]).
//! - Each transaction flushes stale input, writes the packet, and waits for the 2-byte
//!   reply until the modelled response time ([`robobus_wck::timing`]: wire time of the
//!   command and reply plus the module's 1006.6 µs turnaround, or 121 ms for EEPROM
//!   writes) plus [`WckConfig::margin`].
//! - Replies have no checksum: each is checked for plausibility (range, echo, repeated
//!   bytes) and an implausible one is an error, never a value. Reads and idempotent
//!   commands are retried (default three more times); EEPROM settings are verified by
//!   read-back; ID and baud changes by talking to the module at its new ID / rate;
//!   nothing that is not idempotent is ever resent. [`retry_class`] is the one table
//!   of these decisions.
//! - Errors ([`WckError`]) name the device, the module, the command and what arrived.
//!
//! The same code drives a real adapter ([`WckBus::open`] on `/dev/ttyUSB0`) and the
//! simulator (its pseudo-terminal, or any [`ByteLink`](robobus_link::ByteLink)):
//!
//! ```
//! # #[cfg(target_os = "linux")] {
//! use robobus::wck::{WckBus, Gains};
//! use robobus_link::{PtyOptions, PtyPair};
//! use robobus_sim::wck::{Bus, BusConfig, Endpoint, Model};
//! use robobus_wck::{BaudRate, PGain, DGain, Position, ServoId, TorqueLevel};
//!
//! // A simulated bus with servos 0 and 1 behind a pty (as `robobus sim wck` runs it).
//! let pty = PtyPair::open(&PtyOptions::default())?;
//! let sim = Endpoint::spawn(
//!     Bus::with_servos(BusConfig::default(), Model::W1108, [0, 1]),
//!     pty.master,
//!     pty.slave_path.clone(),
//! )?;
//! std::thread::sleep(std::time::Duration::from_millis(70)); // modules power up
//!
//! // A real port: `WckBus::open("/dev/ttyUSB0", BaudRate::B115200)?`; here the pty.
//! let mut bus = WckBus::new(pty.slave, BaudRate::B115200)?;
//! let mut servo = bus.servo(ServoId::new(1)?);
//! let before = servo.move_to(TorqueLevel::new(2)?, Position::new(180)?)?;
//! assert_eq!(before.position.get(), 127); // a move replies the status before moving
//! servo.set_gains(Gains { p: PGain::new(40)?, d: DGain::new(60)? })?; // verified
//! assert_eq!(servo.gains()?.p.get(), 40);
//! # }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod bus;
mod error;
mod policy;
mod scan;
mod servo;

pub use bus::{
    DEFAULT_LATE_WINDOW, DEFAULT_MARGIN, DEFAULT_SETTLE, PTY_MARGIN, PortLink, TCP_MARGIN,
    TURNAROUND_SPREAD, WckBus, WckConfig, WckStats, reply_guard,
};
pub use error::{Hex, WckError};
pub use policy::{RetryClass, needs_confirmation, read_back, retry_class};
pub use scan::{Duplicate, FoundServo, ScanOptions, ScanProgress, ScanReport};
pub use servo::{Gains, IoState, Servo, SpeedAccel, Status, WheelStatus};
