//! Operations: every device operation the `robobus` command offers, as one library call.
//!
//! This is the layer the catalogue's operations run on (the front ends reach it through
//! the catalogue) and a program may call directly. None of the front ends holds device
//! logic of its own; an operation takes typed arguments, has a plan a front end can show,
//! runs it, and returns its typed report.
//!
//! Conventions shared by all operations:
//!
//! - **Typed, validated arguments.** Out-of-range values are refused before anything is
//!   sent ([`OpError::Invalid`], [`ErrorKind::BadInput`]).
//! - **One plan.** An operation whose frames depend on time or on the device first computes
//!   its plan (the exact bytes / frames with their times); a dry-run hands the plan back and
//!   the real run executes the same plan. Where the plan depends on the device (a move
//!   starts where the joint is), the dry-run names the value it assumed.
//! - **Typed reports** derive [`serde::Serialize`]: the CLI's `--json` output is the report,
//!   so every front end gets one schema.
//! - **Per-device results** ([`DeviceResult`]): an operation on many devices reports each one
//!   and carries on past a silent one; the caller decides what the whole run means.
//! - **Stop and progress** ([`Control`]): long operations poll a [`StopToken`] and report
//!   [`Progress`]; on stop they bring the devices to the caller's [`SafeState`] and return
//!   [`OpError::Interrupted`]. The library installs no signal handler: a front end sets the
//!   token from its own (the CLI's Ctrl-C handler, a web request, Python's `KeyboardInterrupt`).
//!
//! ```
//! use robobus::ops::{Control, Progress, StopToken};
//!
//! let stop = StopToken::new();
//! let mut seen = Vec::new();
//! let mut on_progress = |p: &Progress| seen.push(p.done);
//! let mut control = Control::new(&stop).with_progress(&mut on_progress);
//! control.report(&Progress::new("scan", 1, Some(31)));
//! assert!(!control.stopped());
//! stop.stop(); // e.g. from a signal handler or another thread
//! assert!(control.stopped());
//! drop(control);
//! assert_eq!(seen, [1]);
//! ```

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use robobus_link::ByteLink;
use schemars::JsonSchema;
use serde::Serialize;

mod bound;
pub mod capture;
mod family;
mod ids;
pub mod ports;
pub mod preflight;
pub mod protect;
pub mod replay;
pub mod safe;
pub mod wck;
pub mod whj;

pub use crate::error::ErrorKind;
use crate::wck::WckError;
use crate::whj::WhjError;
pub use bound::Bound;
pub use family::Family;
pub use ids::{IdList, ListId, distinct_ids, ids_text};
pub use safe::SafeState;

/// A flag a caller sets to stop a running operation; clones share the flag.
///
/// Operations check it between steps and while they wait, so a stop takes effect within one
/// step (a few milliseconds), then the devices are brought to the chosen safe state.
///
/// A front end whose stop request can only be seen on the thread running the operation
/// (Python's signals, on its main thread) gives it a poll ([`StopToken::with_poll`]): every
/// check asks it too, and a `true` sets the flag.
#[derive(Clone, Default)]
pub struct StopToken(Arc<AtomicBool>, Option<Arc<StopPoll>>);

/// What [`StopToken::with_poll`] takes: `true` asks to stop.
pub type StopPoll = dyn Fn() -> bool + Send + Sync;

impl fmt::Debug for StopToken {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("StopToken")
            .field("stopped", &self.0.load(Ordering::SeqCst))
            .field("poll", &self.1.is_some())
            .finish()
    }
}

impl StopToken {
    /// A token that is not set.
    pub fn new() -> Self {
        Self::default()
    }

    /// The same token, whose every check also calls `poll` (on the checking thread; it
    /// should return at once): `true` sets the flag. Clones made from it share the poll.
    #[must_use]
    pub fn with_poll(mut self, poll: impl Fn() -> bool + Send + Sync + 'static) -> Self {
        self.1 = Some(Arc::new(poll));
        self
    }

    /// Asks every operation holding a clone of this token to stop.
    pub fn stop(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether [`stop`](Self::stop) was called (or the poll asked to stop).
    pub fn is_stopped(&self) -> bool {
        if self.0.load(Ordering::SeqCst) {
            return true;
        }
        if self.1.as_ref().is_some_and(|poll| poll()) {
            self.stop();
            return true;
        }
        false
    }

    /// Clears the flag (a front end reusing one token for several operations).
    pub fn reset(&self) {
        self.0.store(false, Ordering::SeqCst);
    }

    /// The flag itself, for a loop that takes a plain `AtomicBool` (a simulator's
    /// serving loop).
    pub fn flag(&self) -> &AtomicBool {
        &self.0
    }

    /// Sleeps until `deadline` or until the token is set, whichever comes first; returns
    /// `false` when it was stopped. Wakes at least every 5 ms to look at the flag.
    pub fn sleep_until(&self, deadline: Instant) -> bool {
        self.sleep_with(deadline, |until| {
            if let Some(t) = until {
                std::thread::sleep(t.saturating_duration_since(Instant::now()));
            }
            Instant::now()
        })
    }

    /// Like [`StopToken::sleep_until`], on any clock: `clock(None)` reads it,
    /// `clock(Some(t))` lets it reach `t` (sleeping, or advancing a virtual clock) and
    /// reads it.
    pub fn sleep_with(
        &self,
        deadline: Instant,
        mut clock: impl FnMut(Option<Instant>) -> Instant,
    ) -> bool {
        loop {
            if self.is_stopped() {
                return false;
            }
            let now = clock(None);
            if now >= deadline {
                return true;
            }
            clock(Some((now + STOP_SLICE).min(deadline)));
        }
    }

    /// Like [`StopToken::sleep_until`], on `link`'s clock ([`ByteLink::now`]): a
    /// simulator's virtual clock jumps, the wall clock sleeps.
    pub fn sleep_on<L: ByteLink + ?Sized>(&self, link: &mut L, deadline: Instant) -> bool {
        self.sleep_with(deadline, |until| {
            if let Some(t) = until {
                link.sleep_until(t);
            }
            link.now()
        })
    }
}

/// How long a sleep goes on at most before it looks at its stop token again.
const STOP_SLICE: Duration = Duration::from_millis(5);

/// How far a long operation has come.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Progress {
    /// What is being done (`"scan"`, `"move"`, `"wave"`, `"upload"`, ...).
    pub stage: &'static str,
    /// Steps done.
    pub done: u64,
    /// Steps in all, when known.
    pub total: Option<u64>,
    /// A short human-readable note (`"115200 bit/s"`, `"J3"`), if any.
    pub note: Option<String>,
}

impl Progress {
    /// Progress without a note.
    pub const fn new(stage: &'static str, done: u64, total: Option<u64>) -> Self {
        Self {
            stage,
            done,
            total,
            note: None,
        }
    }

    /// The same progress with a note.
    #[must_use]
    pub fn with_note(mut self, note: impl Into<String>) -> Self {
        self.note = Some(note.into());
        self
    }
}

/// What a long operation is given by its caller: a stop token and, optionally, a progress
/// callback.
pub struct Control<'a> {
    stop: StopToken,
    progress: Option<&'a mut dyn FnMut(&Progress)>,
}

impl fmt::Debug for Control<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Control")
            .field("stop", &self.stop)
            .field("progress", &self.progress.is_some())
            .finish()
    }
}

impl<'a> Control<'a> {
    /// Control with this stop token and no progress callback.
    pub fn new(stop: &StopToken) -> Self {
        Self {
            stop: stop.clone(),
            progress: None,
        }
    }

    /// Control that is never stopped and reports no progress (short operations, tests).
    pub fn none() -> Self {
        Self::new(&StopToken::new())
    }

    /// Adds a progress callback.
    #[must_use]
    pub fn with_progress(mut self, f: &'a mut dyn FnMut(&Progress)) -> Self {
        self.progress = Some(f);
        self
    }

    /// The stop token.
    pub const fn token(&self) -> &StopToken {
        &self.stop
    }

    /// Whether the caller asked to stop.
    pub fn stopped(&self) -> bool {
        self.stop.is_stopped()
    }

    /// Reports progress to the callback, if there is one.
    pub fn report(&mut self, p: &Progress) {
        if let Some(f) = self.progress.as_mut() {
            f(p);
        }
    }

    /// Sleeps until `deadline` unless stopped first; `false` when stopped.
    pub fn sleep_until(&self, deadline: Instant) -> bool {
        self.stop.sleep_until(deadline)
    }

    /// Sleeps until `deadline` on `link`'s clock unless stopped first; `false` when
    /// stopped.
    pub fn sleep_on<L: ByteLink + ?Sized>(&self, link: &mut L, deadline: Instant) -> bool {
        self.stop.sleep_on(link, deadline)
    }

    /// Sleeps until `deadline` on any clock ([`StopToken::sleep_with`]) unless stopped
    /// first; `false` when stopped.
    pub fn sleep_with(
        &self,
        deadline: Instant,
        clock: impl FnMut(Option<Instant>) -> Instant,
    ) -> bool {
        self.stop.sleep_with(deadline, clock)
    }
}

/// A failure of one device in a multi-device operation: its kind and its message.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct Failure {
    /// What kind of failure.
    pub kind: ErrorKind,
    /// The full message (names the device).
    pub error: String,
}

impl Failure {
    /// The failure of an error with a kind.
    pub fn of(kind: ErrorKind, error: &dyn fmt::Display) -> Self {
        Self {
            kind,
            error: error.to_string(),
        }
    }
}

impl From<&WckError> for Failure {
    fn from(e: &WckError) -> Self {
        Self::of(e.kind(), e)
    }
}

impl From<&WhjError> for Failure {
    fn from(e: &WhjError) -> Self {
        Self::of(e.kind(), e)
    }
}

impl From<&OpError> for Failure {
    fn from(e: &OpError) -> Self {
        Self::of(e.kind(), e)
    }
}

/// One device's outcome in a multi-device operation: serialized with the device's `id`
/// beside either the value's own fields or `kind` and `error`.
///
/// ```
/// use robobus::ops::{DeviceResult, ErrorKind, Failure};
/// #[derive(serde::Serialize)]
/// struct Pos { position: u8 }
/// let ok = DeviceResult::ok(3u8, Pos { position: 127 });
/// let silent: DeviceResult<u8, Pos> = DeviceResult::failed(4, Failure::of(ErrorKind::NoDevice, &"servo 4 did not answer"));
/// assert!(ok.is_ok() && !silent.is_ok());
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct DeviceResult<I, T> {
    /// The device (servo or joint ID).
    pub id: I,
    /// What happened.
    #[serde(flatten)]
    pub outcome: Outcome<T>,
}

/// The outcome of one device: its value, or its failure.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum Outcome<T> {
    /// The device answered; the value's fields.
    Ok(T),
    /// The device failed.
    Failed(Failure),
}

impl<T> Outcome<T> {
    /// The value converted by `f`; a failure stays as it is.
    pub fn map<U>(self, f: impl FnOnce(T) -> U) -> Outcome<U> {
        match self {
            Self::Ok(v) => Outcome::Ok(f(v)),
            Self::Failed(e) => Outcome::Failed(e),
        }
    }
}

impl<I, T> DeviceResult<I, T> {
    /// A device that answered.
    pub const fn ok(id: I, value: T) -> Self {
        Self {
            id,
            outcome: Outcome::Ok(value),
        }
    }

    /// A device that failed.
    pub const fn failed(id: I, failure: Failure) -> Self {
        Self {
            id,
            outcome: Outcome::Failed(failure),
        }
    }

    /// Whether the device answered.
    pub const fn is_ok(&self) -> bool {
        matches!(self.outcome, Outcome::Ok(_))
    }

    /// The value, if the device answered.
    pub const fn value(&self) -> Option<&T> {
        match &self.outcome {
            Outcome::Ok(v) => Some(v),
            Outcome::Failed(_) => None,
        }
    }

    /// The failure, if the device failed.
    pub const fn failure(&self) -> Option<&Failure> {
        match &self.outcome {
            Outcome::Ok(_) => None,
            Outcome::Failed(f) => Some(f),
        }
    }
}

/// The most serious kind among failed devices (for a caller's exit code): `None` when all
/// answered. Order: interrupted, link, device, no device, refused, bad input.
pub fn worst_kind<'a, I: 'a, T: 'a>(
    results: impl IntoIterator<Item = &'a DeviceResult<I, T>>,
) -> Option<ErrorKind> {
    const fn rank(k: ErrorKind) -> u8 {
        match k {
            ErrorKind::Interrupted => 7,
            ErrorKind::Link => 6,
            ErrorKind::Device => 5,
            ErrorKind::NoDevice => 4,
            ErrorKind::Refused => 3,
            ErrorKind::BadInput => 2,
            ErrorKind::NotAvailable => 1,
        }
    }
    results
        .into_iter()
        .filter_map(|r| r.failure().map(|f| f.kind))
        .max_by_key(|k| rank(*k))
}

/// Why an operation failed as a whole.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OpError {
    /// The wCK client failed.
    #[error(transparent)]
    Wck(#[from] WckError),
    /// The WHJ client failed.
    #[error(transparent)]
    Whj(#[from] WhjError),
    /// An argument is invalid; nothing was sent.
    #[error("{option} {value}: {reason}; nothing was sent")]
    Invalid {
        /// The option or argument (`--amplitude`, `ID`).
        option: String,
        /// The value given.
        value: String,
        /// What is allowed or what is wrong (`allowed: 0..=254`).
        reason: String,
    },
    /// Refused for safety or because of the device's state; nothing (more) was sent.
    #[error("{0}")]
    Refused(String),
    /// The device answered, but not with the state asked for (error bits latched, still
    /// disabled, ...).
    #[error("{0}")]
    Device(String),
    /// Stopped by the caller's token; the devices were brought to the safe state (or the
    /// message says what failed on the way).
    #[error("interrupted{}", .detail.as_deref().map(|d| format!(": {d}")).unwrap_or_default())]
    Interrupted {
        /// What the safe stop did, or what failed during it.
        detail: Option<String>,
    },
    /// A file cannot be read or written, or breaks a limit.
    #[error("{}: {reason}", .path.display())]
    File {
        /// The path.
        path: PathBuf,
        /// What is wrong (`larger than the limit of 1 MiB`, the OS error).
        reason: String,
        /// Bad input (too large, malformed) or a link-like I/O failure.
        kind: ErrorKind,
    },
    /// Not available in this build or on this machine.
    #[error("{0}")]
    NotAvailable(String),
    /// A device stopped answering during an operation (the message names it and says what
    /// was done about it).
    #[error("{0}")]
    NoDevice(String),
    /// A bus could not be opened (no such interface, no CAN FD support, the UDP socket).
    #[error(transparent)]
    Open(#[from] robobus_link::OpenError),
    /// The pre-flight on the simulator refused the run before its first frame: the frame,
    /// its time, the joint and what the simulated joint did (kind *refused*; nothing was
    /// sent).
    #[error("{0}")]
    Preflight(Box<preflight::Refusal>),
}

impl OpError {
    /// What kind of failure this is.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Self::Wck(e) => e.kind(),
            Self::Whj(e) => e.kind(),
            Self::Invalid { .. } => ErrorKind::BadInput,
            Self::Refused(_) | Self::Preflight(_) => ErrorKind::Refused,
            Self::Device(_) => ErrorKind::Device,
            Self::Interrupted { .. } => ErrorKind::Interrupted,
            Self::File { kind, .. } => *kind,
            Self::NotAvailable(_) => ErrorKind::NotAvailable,
            Self::NoDevice(_) => ErrorKind::NoDevice,
            Self::Open(e) => crate::error::open_error_kind(e),
        }
    }

    /// An [`OpError::Invalid`].
    pub fn invalid(
        option: impl Into<String>,
        value: impl fmt::Display,
        reason: impl Into<String>,
    ) -> Self {
        Self::Invalid {
            option: option.into(),
            value: value.to_string(),
            reason: reason.into(),
        }
    }
}

/// The largest file an operation reads unless it says otherwise (robot files, keyframe
/// motions, programs, EEPROM images): 4 MiB.
pub const DEFAULT_FILE_LIMIT: u64 = 4 << 20;

/// Reads a whole text file of at most `limit` bytes: a larger file (or an endless one such
/// as `/dev/zero`) is refused after reading `limit + 1` bytes, never read whole.
pub fn read_bounded(path: &Path, limit: u64) -> Result<String, OpError> {
    use std::io::Read as _;
    let file_error = |reason: String, kind| OpError::File {
        path: path.to_path_buf(),
        reason,
        kind,
    };
    let file = std::fs::File::open(path)
        .map_err(|e| file_error(format!("cannot open: {e}"), io_kind(&e)))?;
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| file_error(format!("cannot read: {e}"), io_kind(&e)))?;
    if bytes.len() as u64 > limit {
        return Err(file_error(
            format!("larger than the limit of {}", human_bytes(limit)),
            ErrorKind::BadInput,
        ));
    }
    String::from_utf8(bytes).map_err(|e| {
        file_error(
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
            ErrorKind::BadInput,
        )
    })
}

/// The kind of a file error: a missing or unreadable file is bad input (the user named it).
fn io_kind(e: &std::io::Error) -> ErrorKind {
    match e.kind() {
        std::io::ErrorKind::NotFound
        | std::io::ErrorKind::PermissionDenied
        | std::io::ErrorKind::IsADirectory
        | std::io::ErrorKind::NotADirectory
        | std::io::ErrorKind::InvalidFilename
        | std::io::ErrorKind::InvalidData => ErrorKind::BadInput,
        // A symlink loop (ELOOP) is a path the user gave that cannot be a file.
        _ if e.raw_os_error() == Some(40) => ErrorKind::BadInput,
        _ => ErrorKind::Link,
    }
}

/// `4 MiB`, `512 KiB`, `100 bytes`.
pub fn human_bytes(n: u64) -> String {
    if n >= 1 << 20 && n.is_multiple_of(1 << 20) {
        format!("{} MiB", n >> 20)
    } else if n >= 1 << 10 && n.is_multiple_of(1 << 10) {
        format!("{} KiB", n >> 10)
    } else {
        format!("{n} bytes")
    }
}

/// A value shown in a message, cut to 64 characters (a user's or a peer's input may be of
/// any length; a message stays readable).
pub fn cut(s: &str) -> String {
    if s.chars().count() > 64 {
        format!("{}...", s.chars().take(64).collect::<String>())
    } else {
        s.to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_bounded_refuses_endless_and_oversized_files() {
        let err = read_bounded(Path::new("/dev/zero"), 1024).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::BadInput);
        assert_eq!(err.to_string(), "/dev/zero: larger than the limit of 1 KiB");
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.txt");
        std::fs::write(&p, "abc").unwrap();
        assert_eq!(read_bounded(&p, 3).unwrap(), "abc");
        assert!(
            read_bounded(&p, 2)
                .unwrap_err()
                .to_string()
                .contains("limit of 2 bytes")
        );
        let missing = read_bounded(&dir.path().join("none"), 3).unwrap_err();
        assert_eq!(missing.kind(), ErrorKind::BadInput);
    }

    #[test]
    fn per_device_results_serialize_flat_and_rank_failures() {
        #[derive(Serialize)]
        struct Pos {
            position: u8,
        }
        let results = [
            DeviceResult::ok(1u8, Pos { position: 127 }),
            DeviceResult::failed(2, Failure::of(ErrorKind::NoDevice, &"servo 2: silent")),
            DeviceResult::failed(3, Failure::of(ErrorKind::Device, &"servo 3: bad reply")),
        ];
        let json = serde_json::to_string(&results).unwrap();
        assert_eq!(
            json,
            r#"[{"id":1,"position":127},{"id":2,"kind":"no-device","error":"servo 2: silent"},{"id":3,"kind":"device","error":"servo 3: bad reply"}]"#
        );
        assert_eq!(worst_kind(&results), Some(ErrorKind::Device));
        assert_eq!(worst_kind(&results[..1]), None);
    }

    #[test]
    fn a_sleep_on_a_link_takes_the_link_clock_and_stops_on_the_token() {
        use robobus_sim::wck::{Bus, BusConfig, SimLink};
        let (mut link, _handle) = SimLink::virtual_clock(Bus::new(BusConfig::default()));
        let token = StopToken::new();
        let start = link.now();
        let deadline = start + Duration::from_secs(60);
        // A minute of the simulator's clock, in no wall time.
        assert!(token.sleep_on(&mut link, deadline));
        assert_eq!(link.now(), deadline);
        token.stop();
        assert!(!token.sleep_on(&mut link, deadline + Duration::from_secs(1)));
        assert_eq!(link.now(), deadline);
    }

    #[test]
    fn a_polled_token_stops_a_sleep_at_its_next_slice_and_stays_stopped() {
        use robobus_sim::wck::{Bus, BusConfig, SimLink};
        let (mut link, _handle) = SimLink::virtual_clock(Bus::new(BusConfig::default()));
        let polls = Arc::new(std::sync::atomic::AtomicU32::new(0));
        let p = Arc::clone(&polls);
        // Asks to stop on its fourth call.
        let token = StopToken::new().with_poll(move || p.fetch_add(1, Ordering::SeqCst) == 3);
        let start = link.now();
        assert!(
            !token
                .clone()
                .sleep_on(&mut link, start + Duration::from_secs(60))
        );
        // Polled before each 5 ms slice: stopped after three slices.
        assert_eq!(link.now(), start + 3 * STOP_SLICE);
        assert_eq!(polls.load(Ordering::SeqCst), 4);
        // The flag is set: no more polls, and a clone without the poll sees it too.
        assert!(token.is_stopped() && StopToken(Arc::clone(&token.0), None).is_stopped());
        assert_eq!(polls.load(Ordering::SeqCst), 4);
    }

    #[test]
    fn stop_token_wakes_a_sleeper_early() {
        let token = StopToken::new();
        let t = token.clone();
        let h = std::thread::spawn(move || t.sleep_until(Instant::now() + Duration::from_secs(30)));
        token.stop();
        assert!(!h.join().unwrap());
        token.reset();
        assert!(token.sleep_until(Instant::now()));
    }
}

// The pre-flight's seed and report are defined at the top of `ops`, where the WHJ motions whose
// reports carry them (`whj::motion`) and the pre-flight (`ops::preflight`, which re-exports
// them) both see them without importing each other.

/// What the simulator is seeded with: one WHJ joint as read from the device.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct WhjSeed {
    /// The joint.
    pub id: u8,
    /// Its model, as `whj info` names it.
    pub model: String,
    /// Its firmware version.
    pub firmware: String,
    /// Where it was, degrees.
    pub position_deg: f64,
    /// Its work mode.
    pub mode: String,
    /// The mode as the simulated joint is set to it.
    #[serde(skip)]
    #[schemars(skip)]
    pub work_mode: robobus_whj::WorkMode,
    /// The firmware as the simulated joint reports it.
    #[serde(skip)]
    #[schemars(skip)]
    pub firmware_version: robobus_whj::units::FirmwareVersion,
    /// Whether its drive was enabled.
    pub enabled: bool,
    /// Its temperature, °C (the simulated joint starts at it).
    pub temperature_c: f64,
    /// Its supply voltage, V.
    pub voltage_v: f64,
    /// Its settings (`whj backup`), restored onto the simulated joint.
    #[serde(skip)]
    #[schemars(skip)]
    pub settings: whj::settings::Settings,
    /// How many settings were copied.
    pub settings_copied: usize,
}

/// A pre-flight that passed: what was simulated, from what seed.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct PreflightReport {
    /// Frames the simulated run sent (the plan's, and a move's repeated last one).
    pub frames: u64,
    /// The simulated run's length, s (simulated time).
    pub simulated_s: f64,
    /// The seed read from the joint.
    pub seed: WhjSeed,
}
