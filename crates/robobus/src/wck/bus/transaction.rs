//! One attempt and its retries: flush, send, the timed read, attribution of the bytes to
//! the command, decoding, and the errors they end in.

use core::time::Duration;

use robobus_link::{ByteLink, LinkError, wait};
use robobus_wck::{Command, Reply, ReplyError, timing};

use super::WckBus;
use crate::wck::error::{Hex, WckError};
use crate::wck::policy::{RetryClass, needs_confirmation, retry_class};

/// Longest a drain after a failed attempt may last, however noisy the line.
const MAX_DRAIN: Duration = Duration::from_millis(50);

/// Most bytes one attempt keeps for its error message (the rest is only counted).
const KEEP_BYTES: usize = 16;

/// Why one attempt failed.
#[derive(Debug)]
pub(crate) enum Failure {
    Timeout {
        received: Vec<u8>,
        waited: Duration,
    },
    Bad {
        bytes: Vec<u8>,
        reason: ReplyError,
    },
    /// Bytes that cannot be this command's one reply (see [`Anomaly`]).
    Unattributable {
        bytes: Vec<u8>,
        anomaly: Anomaly,
    },
    Link(LinkError),
}

/// Why the bytes of an attempt cannot be the command's one reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Anomaly {
    /// `early` bytes arrived before any module can have answered
    /// ([`timing::earliest_reply`]): stray bytes (an earlier reply, a duplicate, noise).
    Early { early: usize },
    /// More bytes than one reply arrived within the guard time after it: more than one
    /// answer.
    Extra { total: usize },
}

impl Anomaly {
    /// The error text: what arrived and why it cannot be the reply.
    pub(crate) fn describe(self, bytes: &[u8], reply_len: usize) -> String {
        match self {
            Self::Early { early } => format!(
                "{early} of the {} byte(s) ({}) arrived before any module can have answered",
                bytes.len().max(early),
                Hex(bytes)
            ),
            Self::Extra { total } => {
                let first = bytes.get(..reply_len).unwrap_or_default();
                let second = bytes.get(reply_len..reply_len * 2).unwrap_or_default();
                if second.len() == reply_len && first != second {
                    format!(
                        "more than one answer: two different replies ({} and {})",
                        Hex(first),
                        Hex(second)
                    )
                } else {
                    format!(
                        "more than one answer: {total} bytes ({}) where one {reply_len}-byte \
                         reply was due",
                        Hex(bytes)
                    )
                }
            }
        }
    }
}
impl<L: ByteLink> WckBus<L> {
    /// One attempt: flush, write, read two bytes before the deadline.
    pub(crate) fn exchange(&mut self, command: &Command) -> Result<[u8; 2], Failure> {
        self.drain_late();
        self.exchange_now(command)
    }

    /// Whether a reply to an earlier attempt may still arrive (its late window is open).
    pub(crate) fn late_reply_possible(&self) -> bool {
        self.quiet_until.is_some_and(|q| q > self.link.now())
    }

    /// Drops (and counts) the input already waiting before a packet is sent: nothing sent
    /// before the packet can be its reply.
    fn drop_waiting(&mut self) -> Result<(), LinkError> {
        let now = self.link.now();
        let mut buf = [0u8; 64];
        // Bounded: a line that never stops sending is flushed after 64 reads.
        for _ in 0..64 {
            match self.link.read_some(&mut buf, now) {
                Ok(n) => self.stats.dropped += n as u64,
                Err(LinkError::Timeout { .. }) => break,
                Err(e) => return Err(e),
            }
        }
        self.link.discard_input()
    }

    /// One attempt without waiting out an open late window first: what it receives may
    /// be an earlier attempt's late reply, so the caller must not credit it while
    /// [`WckBus::late_reply_possible`] said so (see the scan).
    pub(crate) fn exchange_now(&mut self, command: &Command) -> Result<[u8; 2], Failure> {
        self.drop_waiting().map_err(Failure::Link)?;
        let packet = command.encode();
        let wait = self.reply_wait(command);
        let start = self.link.now();
        self.link.write_all(&packet).map_err(Failure::Link)?;
        self.stats.attempts += 1;
        let deadline = start + wait;
        self.deadline = Some(deadline);
        let earliest = start
            + match self.config.min_turnaround {
                Some(t) if command.reply_len() > 0 => {
                    timing::wire_time(command.encoded_len(), self.baud)
                        .saturating_add(t.min(timing::turnaround(command)))
                }
                _ => timing::earliest_reply(command, self.baud),
            };
        let reply_len = command.reply_len();
        let guard = self.config.guard_at(self.baud);
        let mut kept: Vec<u8> = Vec::with_capacity(reply_len);
        let (mut total, mut early) = (0usize, 0usize);
        let mut until = deadline;
        let mut buf = [0u8; KEEP_BYTES];
        let mode = self.config.wait;
        loop {
            // Without a guard time, a whole reply is credited at once: bytes that came
            // with it in the same read still fail it, later ones the next attempt.
            if guard.is_zero() && total - early >= reply_len {
                break;
            }
            // The reply's first byte is due at `earliest`, each next one at once; after a
            // whole reply, nothing is (the guard time must pass quietly).
            let expected = if total - early >= reply_len {
                until
            } else {
                earliest.max(self.link.now())
            };
            match wait::read_some(&mut self.link, &mut buf, until, expected, mode) {
                Ok(n) => {
                    // Received by now: a byte read before the earliest reply instant
                    // arrived before any module can have started answering.
                    let at = self.link.now();
                    if at < earliest {
                        early += n;
                    }
                    total += n;
                    let room = KEEP_BYTES.saturating_sub(kept.len());
                    kept.extend(buf.iter().take(n.min(room)));
                    if total - early >= reply_len {
                        // A reply's worth: the line must now stay quiet for the guard
                        // time (an anomaly is read on until quiet, at most that long
                        // past the deadline, for the error message).
                        until = (at + guard).min(deadline + guard);
                    }
                }
                Err(LinkError::Timeout { .. }) => break,
                Err(e) => return Err(Failure::Link(e)),
            }
        }
        let answered = total - early;
        let anomaly = if early > 0 && answered > 0 {
            Some(Anomaly::Early { early })
        } else if answered > reply_len {
            Some(Anomaly::Extra { total })
        } else {
            None
        };
        if let Some(anomaly) = anomaly {
            self.stats.unattributable += 1;
            self.expect_late();
            return Err(Failure::Unattributable {
                bytes: kept,
                anomaly,
            });
        }
        if answered == reply_len
            && let Some(&[a, b]) = kept.get(early..).map(|k| k.get(..2).unwrap_or_default())
        {
            return Ok([a, b]);
        }
        self.expect_late();
        Err(Failure::Timeout {
            received: kept.get(early..).unwrap_or_default().to_vec(),
            waited: wait,
        })
    }

    /// A reply to the last attempt may still come (it timed out, its reply was garbled,
    /// or it succeeded after a retry): the next packet waits out the late window first.
    pub(crate) fn expect_late(&mut self) {
        if let Some(d) = self.deadline {
            let until = d + self.config.late_window;
            self.quiet_until = Some(self.quiet_until.map_or(until, |q| q.max(until)));
        }
    }

    /// Drops (and counts) input until the late window of the last doubtful attempt has
    /// passed.
    pub(super) fn drain_late(&mut self) {
        let Some(until) = self.quiet_until.take() else {
            return;
        };
        // Until the link says the deadline has passed (a fast-forwarding simulator says
        // so at once, on its own clock).
        let mut buf = [0u8; 64];
        while let Ok(n) = self.link.read_some(&mut buf, until) {
            self.stats.dropped += n as u64;
        }
    }

    /// Bytes that arrive within `window` after a reply (a collision or line noise makes
    /// them; a single clean module sends none). Used by the scan.
    pub(crate) fn trailing_bytes(&mut self, window: Duration) -> Result<usize, WckError> {
        let deadline = self.link.now() + window;
        let mut buf = [0u8; 16];
        let mut n = 0;
        loop {
            match self.link.read_some(&mut buf, deadline) {
                Ok(k) => n += k,
                Err(LinkError::Timeout { .. }) => return Ok(n),
                Err(source) => return Err(self.link_error("scan", source)),
            }
        }
    }

    /// One attempt, decoded; failures are counted.
    pub(crate) fn attempt(&mut self, command: &Command) -> Result<Reply, Failure> {
        let bytes = self.exchange(command).inspect_err(|f| {
            if matches!(f, Failure::Timeout { .. }) {
                self.stats.timeouts += 1;
            }
        })?;
        command.decode_reply(&bytes).map_err(|reason| {
            self.stats.bad_replies += 1;
            self.expect_late();
            Failure::Bad {
                bytes: bytes.to_vec(),
                reason,
            }
        })
    }

    /// Sends a command without a reply, once.
    pub(super) fn send(&mut self, command: &Command) -> Result<(), WckError> {
        self.drain_late();
        self.drop_waiting()
            .and_then(|()| self.link.write_all(&command.encode()))
            .map_err(|source| self.link_error(command.name(), source))?;
        self.stats.attempts += 1;
        Ok(())
    }

    /// One attempt, no resend; a failure drains the line and becomes an error.
    pub(super) fn once(&mut self, command: &Command) -> Result<Reply, WckError> {
        self.attempt(command).map_err(|f| {
            self.settle();
            self.failure_error(command, f, 1)
        })
    }

    /// How many equal replies in a row `command` needs (1 = no confirmation).
    fn agreement(&self, command: &Command) -> u32 {
        let n = u32::from(self.config.confirm_reads).max(1);
        if retry_class(command) != RetryClass::Read {
            1
        } else if needs_confirmation(command) {
            n
        } else {
            (n - 1).max(1)
        }
    }

    /// A read or idempotent command with retries (and confirmation, if configured).
    pub(crate) fn run(&mut self, command: &Command) -> Result<Reply, WckError> {
        let tries = self.config.retries.saturating_add(1);
        let needed = self.agreement(command);
        let limit = tries.saturating_mul(needed);
        let mut previous: Option<[u8; 2]> = None;
        let mut streak = 0;
        let mut failed = false;
        let mut last_error = None;
        for _ in 0..limit {
            if failed {
                self.stats.retries += 1;
            }
            match self.exchange(command) {
                Ok(bytes) => match command.decode_reply(&bytes) {
                    Ok(reply) => {
                        if failed {
                            // This may be an earlier attempt's reply; this one's is late.
                            self.expect_late();
                        }
                        if previous == Some(bytes) {
                            streak += 1;
                        } else {
                            if let Some(p) = previous {
                                self.stats.mismatches += 1;
                                last_error = Some(WckError::Unconfirmed {
                                    device: self.device.clone(),
                                    target: command.target(),
                                    command: command.name(),
                                    previous: p.to_vec(),
                                    last: bytes.to_vec(),
                                    attempts: limit,
                                });
                            }
                            previous = Some(bytes);
                            streak = 1;
                        }
                        if streak >= needed {
                            return Ok(reply);
                        }
                        failed = false;
                    }
                    Err(reason) => {
                        self.stats.bad_replies += 1;
                        self.expect_late();
                        self.settle();
                        failed = true;
                        let bytes = bytes.to_vec();
                        last_error = Some(self.failure_error(
                            command,
                            Failure::Bad { bytes, reason },
                            limit,
                        ));
                    }
                },
                Err(Failure::Link(source)) => {
                    return Err(self.link_error(command.name(), source));
                }
                Err(failure @ Failure::Unattributable { .. }) => {
                    self.settle();
                    failed = true;
                    last_error = Some(self.failure_error(command, failure, limit));
                }
                Err(failure) => {
                    self.stats.timeouts += 1;
                    self.settle();
                    failed = true;
                    last_error = Some(self.failure_error(command, failure, limit));
                }
            }
        }
        Err(last_error.unwrap_or_else(|| WckError::Unconfirmed {
            device: self.device.clone(),
            target: command.target(),
            command: command.name(),
            previous: Vec::new(),
            last: previous.map(|p| p.to_vec()).unwrap_or_default(),
            attempts: limit,
        }))
    }

    /// Reads and drops input until the line is quiet for
    /// [`WckConfig::settle`](super::WckConfig::settle) (at most 50 ms or twice the settle
    /// time), then flushes.
    pub(crate) fn settle(&mut self) {
        let cap = self.link.now() + MAX_DRAIN.max(self.config.settle.saturating_mul(2));
        let mut buf = [0u8; 64];
        loop {
            let now = self.link.now();
            if now >= cap {
                break;
            }
            let deadline = (now + self.config.settle).min(cap);
            match self.link.read_some(&mut buf, deadline) {
                Ok(n) => self.stats.dropped += n as u64,
                Err(_) => break,
            }
        }
        let _ = self.link.discard_input();
    }

    // ----- errors -----

    pub(crate) fn link_error(&self, command: &'static str, source: LinkError) -> WckError {
        WckError::Link {
            device: self.device.clone(),
            command,
            source,
        }
    }

    pub(crate) fn failure_error(
        &self,
        command: &Command,
        failure: Failure,
        attempts: u32,
    ) -> WckError {
        match failure {
            Failure::Timeout { received, waited } => WckError::Timeout {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                baud: self.baud,
                waited,
                received,
                expected: command.reply_len(),
                attempts,
            },
            Failure::Bad { bytes, reason } => WckError::BadReply {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                bytes,
                reason,
                attempts,
            },
            Failure::Unattributable { bytes, anomaly } => WckError::Unattributable {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                detail: anomaly.describe(&bytes, command.reply_len()),
                bytes,
                attempts,
            },
            Failure::Link(source) => self.link_error(command.name(), source),
        }
    }

    /// A decoded reply of the wrong shape (cannot happen: the decoder picks the variant
    /// from the command), reported instead of guessed.
    pub(crate) fn unexpected(&self, command: &Command, reply: Option<Reply>) -> WckError {
        WckError::BadReply {
            device: self.device.clone(),
            target: command.target(),
            command: command.name(),
            bytes: reply.map(|r| r.to_bytes().to_vec()).unwrap_or_default(),
            reason: ReplyError::NoReply {
                command: command.name(),
            },
            attempts: 1,
        }
    }
}
