//! Admission: whether a front end runs a request now, by one rule for every front end
//! (the studio, the bridge, Python).
//!
//! In order, and the first that refuses answers (nothing is sent); a request that does
//! not validate is bad input after the read-only check and before the others:
//!
//! 1. **Read-only.** A front end started read-only runs only [`Effect::Read`] requests,
//!    and never arms ([`Admission::may_arm`]).
//! 2. **Arming.** [`Effect::Motion`] requests and jogs need the front end armed: through
//!    its operator [`Guard`] (the controlling session, armed, with its dead man's switch:
//!    the studio and the bridge), or the admission's own flag for a front end whose caller
//!    is its own operator (Python: armed unless its caller disarms). A guard also refuses
//!    a change from a session that does not control.
//! 3. **The write rate.** At most [`WRITES_PER_MINUTE`] requests whose plan writes
//!    non-volatile memory (the plan's [`ConfirmClass`], as the operation's own check
//!    says it, is not `None`: EEPROM, flash, IDs, the `confirm` registers) within any
//!    [`WRITE_WINDOW`]: they wear the devices' memory. A refused write is not counted.
//!
//! The clock is injected ([`Clock`]): the front ends run on [`WallClock`], the tests on a
//! [`ManualClock`].

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use super::guard::Guard;
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::{Effect, Family, Request};
use crate::ops::OpError;

/// Non-volatile writes admitted within one [`WRITE_WINDOW`].
pub const WRITES_PER_MINUTE: usize = 10;
/// The window of the write rate.
pub const WRITE_WINDOW: Duration = Duration::from_secs(60);

/// Where an admission reads the time.
pub trait Clock: Send + Sync {
    /// Now.
    fn now(&self) -> Instant;
}

/// The system's monotonic clock.
#[derive(Debug, Clone, Copy, Default)]
pub struct WallClock;

impl Clock for WallClock {
    fn now(&self) -> Instant {
        Instant::now()
    }
}

/// A clock that moves only when told ([`ManualClock::advance`]): for tests.
#[derive(Debug, Clone)]
pub struct ManualClock {
    start: Instant,
    offset: Arc<Mutex<Duration>>,
}

impl Default for ManualClock {
    fn default() -> Self {
        Self {
            start: Instant::now(),
            offset: Arc::default(),
        }
    }
}

impl ManualClock {
    /// A clock standing at the time it was made.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Moves it (and every clone) forward by `by`.
    pub fn advance(&self, by: Duration) {
        *self.offset.lock().unwrap_or_else(PoisonError::into_inner) += by;
    }
}

impl Clock for ManualClock {
    fn now(&self) -> Instant {
        self.start + *self.offset.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// How a front end names itself and tells its user what to do, in the one wording of
/// every refusal.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrontEnd {
    /// Its name in a sentence: `this studio`, `this bridge`, `this station`.
    pub name: String,
    /// How it was made read-only: `started with --read-only`.
    pub read_only_how: String,
    /// How its operator arms: `take control and arm first`.
    pub arm_how: String,
}

/// Who arms a front end.
#[derive(Debug, Clone, Copy)]
pub enum Arming<'a> {
    /// Its operator guard, for `session` (`None`: a client without one, which may
    /// change devices only while no session controls, and never move them).
    Guard {
        /// The station's guard.
        guard: &'a Guard,
        /// The session asking.
        session: Option<u64>,
    },
    /// The admission's own flag ([`Admission::arm`], [`Admission::disarm`]).
    Local,
}

/// Why a request was not admitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefusalKind {
    /// The front end is read-only.
    ReadOnly,
    /// Motion while not armed.
    NotArmed,
    /// The guard refused: another session controls (or none was given).
    NotController,
    /// More non-volatile writes than [`WRITES_PER_MINUTE`].
    RateLimited,
    /// The request itself is invalid (its plan failed).
    BadInput,
}

impl RefusalKind {
    /// Its name (`read-only`, `not-armed`, `not-controller`, `rate-limited`,
    /// `bad-input`).
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::ReadOnly => "read-only",
            Self::NotArmed => "not-armed",
            Self::NotController => "not-controller",
            Self::RateLimited => "rate-limited",
            Self::BadInput => "bad-input",
        }
    }
}

/// A request not admitted: why, and the error a front end reports
/// ([`ErrorKind::Refused`](crate::ErrorKind::Refused) but for bad input).
#[derive(Debug)]
pub struct Refusal {
    /// Why.
    pub kind: RefusalKind,
    /// The error, its message in the one wording.
    pub error: OpError,
    /// When the same request may be admitted (a rate-limited write): whole seconds, at
    /// least 1.
    pub retry_after: Option<Duration>,
}

impl Refusal {
    fn refused(kind: RefusalKind, message: String) -> Self {
        Self {
            kind,
            error: OpError::Refused(message),
            retry_after: None,
        }
    }
}

impl From<Refusal> for OpError {
    fn from(r: Refusal) -> Self {
        r.error
    }
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.error.fmt(f)
    }
}

/// A request an [`Admission`] admitted: only [`Admission::admit`] makes one, so a front
/// end that runs `Admitted` requests cannot skip it.
#[derive(Debug)]
pub struct Admitted(Request);

impl Admitted {
    /// The request.
    #[must_use]
    pub const fn request(&self) -> &Request {
        &self.0
    }

    /// The request, to run.
    #[must_use]
    pub fn into_request(self) -> Request {
        self.0
    }
}

/// One front end's admission (see the [module docs](self)).
pub struct Admission {
    front: FrontEnd,
    read_only: bool,
    armed: AtomicBool,
    writes: Mutex<VecDeque<Instant>>,
    clock: Box<dyn Clock>,
}

impl std::fmt::Debug for Admission {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Admission")
            .field("front", &self.front)
            .field("read_only", &self.read_only)
            .field("armed", &self.armed)
            .finish_non_exhaustive()
    }
}

impl Admission {
    /// The admission of `front`, `read_only` or not, on the wall clock; its own flag
    /// ([`Arming::Local`]) disarmed.
    #[must_use]
    pub fn new(front: FrontEnd, read_only: bool) -> Self {
        Self::with_clock(front, read_only, WallClock)
    }

    /// [`Admission::new`] on `clock`.
    #[must_use]
    pub fn with_clock(front: FrontEnd, read_only: bool, clock: impl Clock + 'static) -> Self {
        Self {
            front,
            read_only,
            armed: AtomicBool::new(false),
            writes: Mutex::new(VecDeque::new()),
            clock: Box::new(clock),
        }
    }

    /// Whether it is read-only.
    #[must_use]
    pub const fn read_only(&self) -> bool {
        self.read_only
    }

    /// The front end it speaks for.
    #[must_use]
    pub const fn front_end(&self) -> &FrontEnd {
        &self.front
    }

    /// Whether the front end may arm: not when read-only.
    ///
    /// # Errors
    ///
    /// [`RefusalKind::ReadOnly`].
    pub fn may_arm(&self) -> Result<(), Refusal> {
        if self.read_only {
            return Err(Refusal::refused(
                RefusalKind::ReadOnly,
                format!(
                    "arm: {} is read-only ({}): nothing moves; nothing was sent",
                    self.front.name, self.front.read_only_how
                ),
            ));
        }
        Ok(())
    }

    /// Arms its own flag ([`Arming::Local`]).
    ///
    /// # Errors
    ///
    /// As [`Admission::may_arm`].
    pub fn arm(&self) -> Result<(), Refusal> {
        self.may_arm()?;
        self.armed.store(true, Ordering::SeqCst);
        Ok(())
    }

    /// Disarms its own flag.
    pub fn disarm(&self) {
        self.armed.store(false, Ordering::SeqCst);
    }

    /// Whether its own flag is armed.
    #[must_use]
    pub fn armed(&self) -> bool {
        self.armed.load(Ordering::SeqCst)
    }

    /// Whether `request` runs now (see the [module docs](self)); a motion admitted
    /// through a guard has its devices recorded for the safe stop, a non-volatile write
    /// is counted.
    ///
    /// # Errors
    ///
    /// The first [`Refusal`]: read-only, bad input (the request does not validate), not
    /// armed, not the controller, the write rate.
    pub fn admit(&self, arming: Arming<'_>, request: Request) -> Result<Admitted, Refusal> {
        let effect = request.effect();
        let op = request.op();
        if effect != Effect::Read {
            self.check_change(op)?;
        }
        // Bad input is said as such before anything else: validated as a run validates it,
        // with the class its plan carries, found without a station (a WHJ current
        // target's plan needs the joint's model; its class does not).
        let confirm = request.operation().check().map_err(|e| Refusal {
            kind: RefusalKind::BadInput,
            error: e,
            retry_after: None,
        })?;
        if effect == Effect::Motion && !self.is_armed(arming) {
            return Err(self.not_armed(op));
        }
        if let Arming::Guard { guard, session } = arming {
            guard.admit(session, &request).map_err(|e| Refusal {
                kind: RefusalKind::NotController,
                error: e,
                retry_after: None,
            })?;
        }
        if confirm.class != ConfirmClass::None {
            self.count_write(op)?;
        }
        Ok(Admitted(request))
    }

    /// Whether a jog of `device` on `bus` runs now: read-only, arming, and (through a
    /// guard) the controlling session, which records the device for the safe stop.
    ///
    /// # Errors
    ///
    /// The first [`Refusal`].
    pub fn admit_jog(
        &self,
        arming: Arming<'_>,
        family: Family,
        bus: Option<&str>,
        device: u8,
    ) -> Result<(), Refusal> {
        self.check_motion(arming, &format!("jog of {} {device}", family_name(family)))?;
        if let Arming::Guard { guard, session } = arming {
            guard
                .admit_jog(session, family, bus, device)
                .map_err(|e| Refusal {
                    kind: RefusalKind::NotController,
                    error: e,
                    retry_after: None,
                })?;
        }
        Ok(())
    }

    /// Whether `what` may change a device without moving it (make a servo passive): not
    /// read-only.
    ///
    /// # Errors
    ///
    /// [`RefusalKind::ReadOnly`].
    pub fn check_change(&self, what: &str) -> Result<(), Refusal> {
        if self.read_only {
            return Err(Refusal::refused(
                RefusalKind::ReadOnly,
                format!(
                    "{what}: {} is read-only ({}): only reading requests run; nothing was sent",
                    self.front.name, self.front.read_only_how
                ),
            ));
        }
        Ok(())
    }

    /// Whether `what` may move devices now: not read-only, and armed. Nothing is
    /// recorded (a front end that checks a command whole first, then admits each device
    /// with [`Admission::admit_jog`]).
    ///
    /// # Errors
    ///
    /// [`RefusalKind::ReadOnly`], [`RefusalKind::NotArmed`].
    pub fn check_motion(&self, arming: Arming<'_>, what: &str) -> Result<(), Refusal> {
        if self.read_only {
            return Err(Refusal::refused(
                RefusalKind::ReadOnly,
                format!(
                    "{what}: {} is read-only ({}): nothing moves; nothing was sent",
                    self.front.name, self.front.read_only_how
                ),
            ));
        }
        if !self.is_armed(arming) {
            return Err(self.not_armed(what));
        }
        Ok(())
    }

    fn is_armed(&self, arming: Arming<'_>) -> bool {
        match arming {
            Arming::Guard { guard, session } => session.is_some_and(|s| {
                let v = guard.view(s);
                v.controller && v.armed
            }),
            Arming::Local => self.armed(),
        }
    }

    fn not_armed(&self, what: &str) -> Refusal {
        Refusal::refused(
            RefusalKind::NotArmed,
            format!(
                "{what}: not armed: motion needs {} armed ({}); nothing was sent",
                self.front.name, self.front.arm_how
            ),
        )
    }

    /// Counts one non-volatile write now, or refuses it when the window is full.
    fn count_write(&self, op: &str) -> Result<(), Refusal> {
        let mut writes = self.writes.lock().unwrap_or_else(PoisonError::into_inner);
        let now = self.clock.now();
        while writes
            .front()
            .is_some_and(|t| now.saturating_duration_since(*t) >= WRITE_WINDOW)
        {
            writes.pop_front();
        }
        if writes.len() >= WRITES_PER_MINUTE {
            // The oldest write leaves the window first.
            let left = writes.front().map_or(WRITE_WINDOW, |t| {
                WRITE_WINDOW.saturating_sub(now.saturating_duration_since(*t))
            });
            let wait = left.as_secs() + u64::from(left.subsec_nanos() > 0);
            let wait = wait.max(1);
            return Err(Refusal {
                kind: RefusalKind::RateLimited,
                error: OpError::Refused(format!(
                    "{op}: at most {WRITES_PER_MINUTE} EEPROM / flash / ID writes a minute \
                     (they wear the device's memory); try again in {wait} s; nothing was sent"
                )),
                retry_after: Some(Duration::from_secs(wait)),
            });
        }
        writes.push_back(now);
        Ok(())
    }
}

const fn family_name(f: Family) -> &'static str {
    match f {
        Family::Wck => "wck servo",
        Family::Whj => "whj joint",
        Family::Robot => "robot joint",
        Family::Host => "host",
    }
}

#[cfg(test)]
mod tests;
