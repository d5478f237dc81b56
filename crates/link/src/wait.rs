//! How a client waits for a reply it expects at a known instant: in the kernel
//! ([`WaitMode::Sleep`]), or in the kernel until shortly before the reply can come and then
//! polling without blocking ([`WaitMode::Spin`]).
//!
//! A blocked thread costs no CPU, but it is woken by the kernel when the data arrives,
//! and that wake-up takes tens of microseconds on a loaded machine (more when another
//! virtual machine holds the core), which is a large share of a wCK transaction at
//! 921600 bit/s (65 µs) or of a WHJ request at 5 Mbit/s (about 130 µs). A thread that polls
//! sees the data as soon as the kernel has it, and ends a timed wait on time, at the
//! price of one core busy for the polled stretch. The stretch is bounded: it starts
//! `before` the earliest instant a reply can arrive (the protocol's timing model gives it)
//! and ends at the reply or its deadline, so a silent device costs its timeout in
//! either mode.
//!
//! A timed wait in the kernel ends late by the thread's *timer slack* as well: Linux lets
//! every timer of a thread fire up to that much after its deadline so that wake-ups can be
//! grouped, 50 µs by default, which is most of an arbitration loser's frame (the WHJ
//! client's reply hold) and more than a wCK byte at 921600 bit/s. So the first wait of a
//! thread here on a real clock sets that thread's slack to 1 ns ([`precise_timers`]):
//! every later timed wait of the thread (a reply's deadline, a hold's end, a cyclic
//! period) then wakes as soon as the scheduler runs it. It stays set for the thread (a
//! caller's thread that waits on a bus once is a bus thread); elsewhere than Linux there
//! is no such setting.
//!
//! [`read_some`], [`recv`] and [`sleep_until`] take the mode and wait on any link. On a
//! link with a virtual clock ([`ByteLink::virtual_time`]) a poll cannot let time pass, so
//! the polled stretch advances in steps of [`VIRTUAL_POLL_STEP`] there; each step returns
//! as soon as data arrives, so what is received, and when, is the same in both modes.

use core::fmt;
use core::str::FromStr;
use core::time::Duration;
use std::time::Instant;

use crate::{ByteLink, FrameLink, FrameLinkError, LinkError, Received};

/// How early before the expected reply [`WaitMode::SPIN`] starts polling: more than a
/// wake-up's usual lateness, so the poll is running when the reply comes.
pub const DEFAULT_SPIN_BEFORE: Duration = Duration::from_micros(100);

/// The longest stretch a polled wait may block in one step on a virtual clock.
pub const VIRTUAL_POLL_STEP: Duration = Duration::from_micros(5);

/// Longest `before` a spin accepts from text (a second of polling is a mistake).
pub const MAX_SPIN_BEFORE: Duration = Duration::from_secs(1);

/// How a bus waits for replies and timed instants. See the [module notes](self).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum WaitMode {
    /// Block in the kernel until the data or the deadline (the default): no CPU while
    /// waiting, one thread wake-up per reply.
    #[default]
    Sleep,
    /// Block until `before` ahead of the earliest instant the reply can arrive, then poll
    /// without blocking until it arrives or the deadline passes: no wake-up on the reply's
    /// path, a core busy for the polled stretch.
    Spin {
        /// How long before the expected instant polling starts.
        before: Duration,
    },
}

impl WaitMode {
    /// [`WaitMode::Spin`] starting [`DEFAULT_SPIN_BEFORE`] ahead.
    pub const SPIN: Self = Self::Spin {
        before: DEFAULT_SPIN_BEFORE,
    };

    /// The names [`WaitMode::from_str`] accepts, for help texts.
    pub const SYNTAX: &'static str = "sleep, spin or spin:<µs before the reply>";

    /// Whether this mode polls.
    pub const fn spins(self) -> bool {
        matches!(self, Self::Spin { .. })
    }

    /// The instant polling starts for a wait whose data cannot come before `expected`
    /// (`None` in [`WaitMode::Sleep`]).
    fn spin_from(self, expected: Instant) -> Option<Instant> {
        match self {
            Self::Sleep => None,
            Self::Spin { before } => Some(expected.checked_sub(before).unwrap_or(expected)),
        }
    }
}

impl fmt::Display for WaitMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Sleep => f.write_str("sleep"),
            Self::Spin { before } if *before == DEFAULT_SPIN_BEFORE => f.write_str("spin"),
            Self::Spin { before } => write!(f, "spin:{}", before.as_micros()),
        }
    }
}

/// A wait mode that is not one of [`WaitMode::SYNTAX`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "wait mode {given:?} is not {syntax} (spin:<µs> from 0 to {max} µs)",
    syntax = WaitMode::SYNTAX,
    max = MAX_SPIN_BEFORE.as_micros()
)]
pub struct WaitModeError {
    /// The text given.
    pub given: String,
}

impl FromStr for WaitMode {
    type Err = WaitModeError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || WaitModeError {
            given: s.chars().take(64).collect(),
        };
        match s.trim() {
            "sleep" => Ok(Self::Sleep),
            "spin" => Ok(Self::SPIN),
            other => {
                let micros = other
                    .strip_prefix("spin:")
                    .and_then(|m| m.trim().trim_end_matches("us").parse::<u64>().ok())
                    .ok_or_else(bad)?;
                let before = Duration::from_micros(micros);
                if before > MAX_SPIN_BEFORE {
                    return Err(bad());
                }
                Ok(Self::Spin { before })
            }
        }
    }
}

/// Sets the calling thread's timer slack to 1 ns, once per thread (see the
/// [module notes](self)): a timed wait then ends when the kernel's timer fires, not up to
/// the default 50 µs later. Returns whether the thread's slack is that now (always `false`
/// elsewhere than Linux, and where the kernel refused it).
pub fn precise_timers() -> bool {
    #[cfg(target_os = "linux")]
    {
        use std::cell::Cell;
        thread_local! {
            static SET: Cell<Option<bool>> = const { Cell::new(None) };
        }
        SET.with(|set| {
            set.get().unwrap_or_else(|| {
                let ok = nix::sys::prctl::set_timerslack(PRECISE_SLACK_NS).is_ok();
                set.set(Some(ok));
                ok
            })
        })
    }
    #[cfg(not(target_os = "linux"))]
    {
        false
    }
}

/// The timer slack [`precise_timers`] sets: the least Linux takes (0 would mean the
/// process's default).
#[cfg(target_os = "linux")]
const PRECISE_SLACK_NS: std::os::raw::c_ulong = 1;

/// A link's receive, as [`wait_with`] drives it.
trait Poll {
    type Item;
    type Error;
    fn now(&self) -> Instant;
    fn virtual_time(&self) -> bool;
    /// Waits for data until `until` at most: `Ok(None)` when none came.
    fn poll_until(&mut self, until: Instant) -> Result<Option<Self::Item>, Self::Error>;
}

/// [`ByteLink::read_some`] into `buf`.
struct Bytes<'a, L: ?Sized> {
    link: &'a mut L,
    buf: &'a mut [u8],
}

impl<L: ByteLink + ?Sized> Poll for Bytes<'_, L> {
    type Item = usize;
    type Error = LinkError;

    fn now(&self) -> Instant {
        self.link.now()
    }

    fn virtual_time(&self) -> bool {
        self.link.virtual_time()
    }

    fn poll_until(&mut self, until: Instant) -> Result<Option<usize>, LinkError> {
        match self.link.read_some(self.buf, until) {
            Ok(n) => Ok(Some(n)),
            Err(LinkError::Timeout { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    }
}

/// [`FrameLink::recv`].
struct Frames<'a, L: ?Sized>(&'a mut L);

impl<L: FrameLink + ?Sized> Poll for Frames<'_, L> {
    type Item = Received;
    type Error = FrameLinkError;

    fn now(&self) -> Instant {
        self.0.now()
    }

    fn virtual_time(&self) -> bool {
        self.0.virtual_time()
    }

    fn poll_until(&mut self, until: Instant) -> Result<Option<Received>, FrameLinkError> {
        match self.0.recv(until) {
            Ok(rx) => Ok(Some(rx)),
            Err(FrameLinkError::Timeout) => Ok(None),
            Err(e) => Err(e),
        }
    }
}

/// One wait on a link, whatever its kind, in `mode`: the data, or `None` at the deadline.
fn wait_with<P: Poll>(
    p: &mut P,
    mode: WaitMode,
    deadline: Instant,
    expected: Instant,
) -> Result<Option<P::Item>, P::Error> {
    if !p.virtual_time() {
        precise_timers();
    }
    let Some(spin_from) = mode.spin_from(expected) else {
        return p.poll_until(deadline);
    };
    // In the kernel until the polled stretch begins (data that comes earlier ends it).
    if p.now() < spin_from.min(deadline)
        && let Some(got) = p.poll_until(spin_from.min(deadline))?
    {
        return Ok(Some(got));
    }
    let virtual_time = p.virtual_time();
    loop {
        let t = p.now();
        let until = if virtual_time {
            (t + VIRTUAL_POLL_STEP).min(deadline)
        } else {
            // A deadline that has passed: only what is there already, without blocking.
            t
        };
        if let Some(got) = p.poll_until(until)? {
            return Ok(Some(got));
        }
        if p.now() >= deadline {
            return Ok(None);
        }
        core::hint::spin_loop();
    }
}

/// [`ByteLink::read_some`] in `mode`, for data that cannot come before `expected`.
///
/// Errors: as [`ByteLink::read_some`] ([`LinkError::Timeout`] at the deadline).
pub fn read_some<L: ByteLink + ?Sized>(
    link: &mut L,
    buf: &mut [u8],
    deadline: Instant,
    expected: Instant,
    mode: WaitMode,
) -> Result<usize, LinkError> {
    if buf.is_empty() {
        return Ok(0);
    }
    let expected_len = buf.len();
    wait_with(&mut Bytes { link, buf }, mode, deadline, expected)?.ok_or(LinkError::Timeout {
        received: 0,
        expected: expected_len,
    })
}

/// [`FrameLink::recv`] in `mode`, for a frame that cannot come before `expected`.
///
/// Errors: as [`FrameLink::recv`] ([`FrameLinkError::Timeout`] at the deadline).
pub fn recv<L: FrameLink + ?Sized>(
    link: &mut L,
    deadline: Instant,
    expected: Instant,
    mode: WaitMode,
) -> Result<Received, FrameLinkError> {
    wait_with(&mut Frames(link), mode, deadline, expected)?.ok_or(FrameLinkError::Timeout)
}

/// [`FrameLink::sleep_until`] in `mode`: in [`WaitMode::Spin`] the link sleeps until
/// `before` ahead of `deadline` and then polls its clock, so the wait ends on time.
pub fn sleep_until<L: FrameLink + ?Sized>(link: &mut L, deadline: Instant, mode: WaitMode) {
    if !link.virtual_time() {
        precise_timers();
    }
    match mode.spin_from(deadline) {
        Some(from) if !link.virtual_time() => {
            if link.now() < from {
                link.sleep_until(from);
            }
            while link.now() < deadline {
                core::hint::spin_loop();
            }
        }
        _ => link.sleep_until(deadline),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MemoryByteLink;

    /// A thread's first wait on a real clock sets its timer slack to 1 ns; a wait on a
    /// virtual clock leaves it alone. Each case in a fresh thread (the default slack is
    /// the process's, 50 µs unless set otherwise).
    #[cfg(target_os = "linux")]
    #[test]
    fn a_wait_on_a_real_clock_makes_the_threads_timers_precise() {
        use nix::sys::prctl::get_timerslack;
        let slack_after = |virtual_clock: bool| {
            std::thread::spawn(move || {
                let before = get_timerslack().unwrap();
                if virtual_clock {
                    let t0 = Instant::now();
                    let mut link = OneFrame {
                        now: t0,
                        due: None,
                        calls: 0,
                    };
                    let _ = recv(&mut link, t0, t0, WaitMode::Sleep);
                } else {
                    let (mut link, _other) = MemoryByteLink::pair();
                    let now = link.now();
                    let mut buf = [0_u8; 1];
                    let _ = read_some(&mut link, &mut buf, now, now, WaitMode::Sleep);
                }
                (before, get_timerslack().unwrap())
            })
            .join()
            .unwrap()
        };
        let (before, after) = slack_after(false);
        assert_ne!(
            before, 1,
            "the test needs a thread whose slack is not 1 ns already"
        );
        assert_eq!(after, 1);
        let (before, after) = slack_after(true);
        assert_eq!(after, before);
    }

    #[test]
    fn modes_parse_and_print_back() {
        for (text, mode) in [
            ("sleep", WaitMode::Sleep),
            ("spin", WaitMode::SPIN),
            (
                "spin:30",
                WaitMode::Spin {
                    before: Duration::from_micros(30),
                },
            ),
        ] {
            assert_eq!(text.parse::<WaitMode>(), Ok(mode));
            assert_eq!(mode.to_string(), text);
        }
        assert_eq!(
            "spin:30us"
                .parse::<WaitMode>()
                .map(|m| m.to_string())
                .as_deref(),
            Ok("spin:30")
        );
        for bad in ["", "busy", "spin:", "spin:-1", "spin:1000001"] {
            let e = bad.parse::<WaitMode>().unwrap_err();
            assert_eq!(e.given, bad);
            assert!(e.to_string().contains("sleep, spin or spin:"), "{e}");
        }
    }

    #[test]
    fn a_spinning_read_returns_the_data_and_times_out_at_the_deadline() {
        let (mut a, mut b) = MemoryByteLink::pair();
        let t0 = Instant::now();
        let mut buf = [0u8; 4];
        let silent = read_some(
            &mut a,
            &mut buf,
            t0 + Duration::from_millis(3),
            t0 + Duration::from_millis(1),
            WaitMode::SPIN,
        );
        assert!(
            matches!(
                silent,
                Err(LinkError::Timeout {
                    received: 0,
                    expected: 4
                })
            ),
            "{silent:?}"
        );
        assert!(t0.elapsed() >= Duration::from_millis(3));
        b.write_all(&[1, 2]).unwrap();
        let now = Instant::now();
        let n = read_some(
            &mut a,
            &mut buf,
            now + Duration::from_secs(5),
            now,
            WaitMode::SPIN,
        )
        .unwrap();
        assert_eq!(buf.get(..n), Some(&[1u8, 2][..]));
    }

    /// A frame link on a virtual clock with one frame due at `due`; counts receives.
    struct OneFrame {
        now: Instant,
        due: Option<Instant>,
        calls: u32,
    }

    impl FrameLink for OneFrame {
        fn send(&mut self, _: &robobus_whj::CanFrame) -> Result<(), FrameLinkError> {
            Ok(())
        }

        fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
            self.calls += 1;
            match self.due {
                Some(t) if t <= deadline => {
                    self.now = self.now.max(t);
                    self.due = None;
                    let frame = robobus_whj::CanFrame::new_fd(
                        robobus_whj::CanFrame::standard_id(0x107).unwrap(),
                        &[1],
                    )
                    .unwrap();
                    Ok(Received {
                        frame,
                        timestamp: None,
                    })
                }
                _ => {
                    self.now = self.now.max(deadline);
                    Err(FrameLinkError::Timeout)
                }
            }
        }

        fn set_filters(&mut self, _: &[crate::IdFilter]) -> Result<(), FrameLinkError> {
            Ok(())
        }

        fn now(&self) -> Instant {
            self.now
        }

        fn virtual_time(&self) -> bool {
            true
        }
    }

    #[test]
    fn spinning_polls_from_before_the_expected_instant_and_receives_at_the_same_time() {
        let t0 = Instant::now();
        let us = Duration::from_micros;
        let run = |mode| {
            let mut link = OneFrame {
                now: t0,
                due: Some(t0 + us(300)),
                calls: 0,
            };
            let got = recv(&mut link, t0 + us(1000), t0 + us(250), mode);
            (got.is_ok(), link.now - t0, link.calls)
        };
        // Sleeping: one receive, ended by the frame.
        assert_eq!(run(WaitMode::Sleep), (true, us(300), 1));
        // Spinning 100 µs ahead: blocked until 150 µs, then 5 µs polls; the 30th takes
        // the frame at 300 µs.
        assert_eq!(run(WaitMode::SPIN), (true, us(300), 1 + 30));
        // Nothing comes: both end at the deadline.
        let mut silent = OneFrame {
            now: t0,
            due: None,
            calls: 0,
        };
        let got = recv(&mut silent, t0 + us(1000), t0 + us(250), WaitMode::SPIN);
        assert!(matches!(got, Err(FrameLinkError::Timeout)));
        assert_eq!(silent.now - t0, us(1000));
    }
}
