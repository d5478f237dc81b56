//! Simulated wCK servos on a wire-timed multi-drop UART bus.
//!
//! * [`Servo`]: one module, the firmware as a state machine over the typed commands that
//!   [`robobus_wck::StreamDecoder`] decodes (every command of the manual's A-1, with the
//!   reply bytes a module sends), EEPROM and runtime parameters ([`Eeprom`], [`Runtime`];
//!   defaults of A-5), the self-running motion program, I/O, and [`Mechanics`] (motor,
//!   gearbox and position loop; see that module for the model) for the [`Model`]s 1108,
//!   1111 and 1413.
//! * [`Bus`]: the modules on one wire. Every host byte reaches every module; each module
//!   receives the wire's bit waveform with its own UART at its own baud rate (a module at
//!   another rate reads garbage, as a real one does); replies are driven onto a shared
//!   wired-AND line and read by the host's UART at the host's rate, so two modules with
//!   the same ID garble each other bit by bit, and a reply byte reaches the host the
//!   instant its stop bit ends. Seeded faults ([`Faults`]) and module faults (power off /
//!   on, unplug).
//! * [`VirtualHost`]: a host on the virtual clock for deterministic tests.
//! * [`SimLink`]: the bus as an in-process byte link on the wall clock, whose replies do
//!   not depend on thread scheduling (for client tests on a loaded machine).
//! * [`endpoint`]: the bus behind a pseudo-terminal (Unix; [`spawn`] opens the pty and
//!   serves it) or a TCP listener (every OS; [`spawn_tcp`], `socket://HOST:PORT`) on the
//!   wall clock.
//!
//! # Where the manual is silent
//!
//! Each choice is made once, here or in the item named:
//!
//! * Baud mismatch: modelled at bit level (see the `uart` module notes in [`Bus`]): each
//!   receiver samples the wire's waveform in the middle of its own bit times, so a module
//!   at another rate decodes what a real UART would (usually garbage that fails the
//!   checksum), and the host reads a module's reply at the host's rate.
//! * Collisions: the reply wire is a wired-AND; every module has a fixed extra turnaround
//!   of 0..=[`BusConfig::max_skew`] (seeded), so duplicate IDs interfere bit by bit.
//! * Break (broadcast) is answered by every module that hears it: with more than one
//!   module the replies collide, as they would on a real wire.
//! * Busy: from the end of a command until its reply is out (or the EEPROM write is done)
//!   a module ignores the bus; commands without a reply do not make it busy.
//! * Passive reply: the mode byte is sent as `0x10` (the typed command does not keep the
//!   "arbitrary" low nibble).
//! * Wheel: counter-clockwise increases the angle and counts rotations up, clockwise down;
//!   the count byte wraps (0..=255).
//! * Power-up: runtime values from EEPROM, outputs off, rotation count 0, motor passive,
//!   deaf for 65 ms; the motion program (if any) starts.
//! * See [`Servo`] for reads, baud set, boundaries, 10-bit torque and the motion program,
//!   and [`mechanics`] for the physical model.
//!
//! Timing follows the wire-timing notes through [`robobus_wck::timing`]: a reply starts
//! [`Timing::turnaround`] (1006.6 µs) after the last command byte, or
//! [`Timing::eeprom_write`] (121 ms) after an EEPROM write, during which the module does
//! not listen; a module is deaf for 65 ms after power-up. [`Timing::ZERO`] removes all of
//! it for benchmarks.
//!
//! ```
//! use core::time::Duration;
//! use robobus_sim::wck::{Bus, BusConfig, Model, VirtualHost};
//! use robobus_wck::{Command, Position, ServoId, TorqueLevel};
//!
//! let bus = Bus::with_servos(BusConfig::default(), Model::W1108, [0, 1, 2]);
//! let mut host = VirtualHost::new(bus);
//! host.sleep(Duration::from_millis(70));
//! let id = ServoId::new(2)?;
//! let go = Command::Move { id, torque: TorqueLevel::new(0)?, position: Position::new(200)? };
//! let reply = host.command(&go); // load, position before the move
//! assert_eq!(reply, vec![0, 127]);
//! host.sleep(Duration::from_millis(400));
//! let now = host.command(&Command::StatusRead { id });
//! assert!(now[1].abs_diff(200) <= 1, "{now:?}");
//! # Ok::<(), robobus_wck::RangeError>(())
//! ```

mod bus;
mod clock;
pub mod endpoint;
mod link;
pub mod mechanics;
mod model;
mod params;
mod servo;
mod uart;

pub use bus::{Bus, BusConfig, BusStats, Faults};
pub use clock::VirtualHost;
pub use endpoint::{Endpoint, EndpointError, EndpointStats, spawn_tcp};
#[cfg(unix)]
pub use endpoint::{spawn, spawn_waiting};
pub use link::{SimHandle, SimLink};
pub use mechanics::{Drive, Mechanics};
pub use model::{Model, UnknownModel};
pub use params::{Eeprom, EepromFileError, Runtime};
pub use servo::{Answer, Mode, Outcome, Servo, TICK, Timing};
