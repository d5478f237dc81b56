//! Finding the modules on a bus: every ID at one baud rate, or at every rate, with
//! duplicate-ID detection.

use core::ops::RangeInclusive;
use core::time::Duration;

use robobus_link::ByteLink;
use robobus_wck::{BaudRate, Command, ExtServoId, Position10, Reply, ServoId, timing};

use super::bus::{Anomaly, Failure, WckBus};
use super::error::{Hex, WckError};
use super::servo::Status;

/// The largest angle difference (degrees) between a module's 8-bit and 10-bit position
/// readings that still counts as one module: half a step of each (0.53° + 0.16°) plus
/// the shaft moving between the two reads.
const POSITION_AGREEMENT_DEG: f64 = 3.5;

/// What to scan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScanOptions {
    /// The baud rates to try, in order; empty means the bus's current rate.
    pub bauds: Vec<BaudRate>,
    /// The IDs to try (IDs above 30 are skipped: only the 10-bit commands reach them).
    pub ids: RangeInclusive<u8>,
    /// Status reads per ID before it counts as absent (a single lost command must not
    /// hide a module). Default 2.
    pub probes: u32,
    /// Whether to look for two modules sharing an ID (three extra reads per module
    /// found). Default on.
    pub check_duplicates: bool,
    /// Further probes that must all show evidence before an ID is reported as shared
    /// (line noise makes single probes look like a collision). Default 3.
    pub confirm: u32,
}

impl Default for ScanOptions {
    /// Every ID at the bus's current rate, duplicate check on.
    fn default() -> Self {
        Self {
            bauds: Vec::new(),
            ids: 0..=30,
            probes: 2,
            check_duplicates: true,
            confirm: 3,
        }
    }
}

impl ScanOptions {
    /// Every ID at `baud`.
    pub fn at(baud: BaudRate) -> Self {
        Self {
            bauds: vec![baud],
            ..Self::default()
        }
    }

    /// Every ID at every rate a wCK module supports, fastest first (auto-detection).
    pub fn all_bauds() -> Self {
        let mut bauds = BaudRate::ALL.to_vec();
        bauds.reverse();
        Self {
            bauds,
            ..Self::default()
        }
    }

    /// Only the IDs in `ids`.
    #[must_use]
    pub fn ids(mut self, ids: RangeInclusive<u8>) -> Self {
        self.ids = ids;
        self
    }
}

/// Where a scan is, passed to the progress callback after each ID.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScanProgress {
    /// The rate being scanned.
    pub baud: BaudRate,
    /// The ID just probed.
    pub id: ServoId,
    /// Probes done so far (over all rates).
    pub done: usize,
    /// Probes in the whole scan.
    pub total: usize,
    /// Modules found so far (duplicates included).
    pub found: usize,
}

/// A module that answered cleanly.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FoundServo {
    /// Its ID.
    pub id: ServoId,
    /// The rate it answered at.
    pub baud: BaudRate,
    /// Its load and position when probed.
    pub status: Status,
}

/// An ID whose replies show that more than one module answers (their replies collide
/// on the wire), or that something else is wrong with whatever answers there.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Duplicate {
    /// The ID.
    pub id: ServoId,
    /// The rate.
    pub baud: BaudRate,
    /// What was seen, for a human.
    pub evidence: String,
}

/// The result of [`WckBus::scan`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ScanReport {
    /// Modules that answered cleanly, in scan order.
    pub found: Vec<FoundServo>,
    /// IDs answered by more than one module (or garbled); not in `found`.
    pub duplicates: Vec<Duplicate>,
}

impl ScanReport {
    /// The rates at which something answered, in scan order, without repeats.
    pub fn bauds(&self) -> Vec<BaudRate> {
        let mut out = Vec::new();
        let all = self
            .found
            .iter()
            .map(|f| f.baud)
            .chain(self.duplicates.iter().map(|d| d.baud));
        for b in all {
            if !out.contains(&b) {
                out.push(b);
            }
        }
        out
    }

    /// Whether the scan found no module and no duplicate.
    pub fn is_empty(&self) -> bool {
        self.found.is_empty() && self.duplicates.is_empty()
    }
}

enum Probe {
    Absent,
    Found(Status),
    Duplicate(String),
}

impl<L: ByteLink> WckBus<L> {
    /// Probes every ID of `options` at each of its baud rates with status reads, calling
    /// `progress` after each ID. Restores the bus's baud rate at the end.
    ///
    /// An ID counts as absent when [`ScanOptions::probes`] status reads bring no byte at
    /// all (bytes that cannot be its reply, such as a stray byte before any module can
    /// have answered, make it a suspect that is probed again, never an absent ID). A silent ID costs only those reads' reply waits: the next probe goes out at
    /// once, and a reply that arrives while a silent attempt's late window
    /// ([`WckConfig::late_window`](super::WckConfig::late_window)) is still open is not
    /// credited; the window is waited out and the ID asked again. With [`ScanOptions::check_duplicates`], a module that answers is read three
    /// more ways, and the ID is reported as a [`Duplicate`] instead of a [`FoundServo`]
    /// if anything shows that more than one module answers, where a single module
    /// would answer cleanly:
    ///
    /// - bytes missing, extra bytes after the 2-byte reply, or an implausible reply
    ///   (colliding replies garble each other, most of all at high rates);
    /// - the 8-bit (status) and 10-bit positions disagree by more than 3.5°: colliding
    ///   replies on the wired-AND line read as the bitwise AND of the two replies, which
    ///   is a plausible 8-bit position but a different angle than the AND of the two
    ///   10-bit positions, unless the shafts stand at the same angle;
    /// - the I gain or over-load reply, which repeats one value in both bytes, does not.
    ///
    /// Two modules in exactly the same state answering in lock-step are indistinguishable
    /// on the wire; they are caught as soon as their shafts stand apart.
    ///
    /// A scan at a rate other than a module's sends it garbage; the wCK checksum makes an
    /// accidental command unlikely but not impossible.
    pub fn scan(
        &mut self,
        options: &ScanOptions,
        mut progress: impl FnMut(&ScanProgress),
    ) -> Result<ScanReport, WckError> {
        let original = self.baud();
        let bauds = if options.bauds.is_empty() {
            vec![original]
        } else {
            options.bauds.clone()
        };
        let ids: Vec<ServoId> = options
            .ids
            .clone()
            .filter_map(|id| ServoId::new(id).ok())
            .collect();
        let total = bauds.len() * ids.len();
        let mut report = ScanReport::default();
        let mut done = 0;
        let result = (|| {
            for &baud in &bauds {
                self.set_host_baud(baud)?;
                for &id in &ids {
                    match self.confirmed_probe(id, options)? {
                        Probe::Absent => {}
                        Probe::Found(status) => report.found.push(FoundServo { id, baud, status }),
                        Probe::Duplicate(evidence) => {
                            report.duplicates.push(Duplicate { id, baud, evidence });
                        }
                    }
                    done += 1;
                    progress(&ScanProgress {
                        baud,
                        id,
                        done,
                        total,
                        found: report.found.len() + report.duplicates.len(),
                    });
                }
            }
            Ok(())
        })();
        let restored = self.set_host_baud(original);
        result?;
        restored?;
        Ok(report)
    }

    /// One ID, with a suspected duplicate confirmed: a single garbled, truncated or
    /// disagreeing reply is as likely line noise as two modules, so the ID is probed again
    /// (up to [`ScanOptions::confirm`] more times, each probe reading it four ways). It is
    /// reported as a duplicate only if every further probe shows evidence too; one clean
    /// probe makes it a found servo (with that probe's status). A servo that answered is
    /// never dropped: if the further probes neither confirm nor clear it, it stays a
    /// suspected duplicate, with the evidence.
    fn confirmed_probe(&mut self, id: ServoId, options: &ScanOptions) -> Result<Probe, WckError> {
        let first = self.probe(id, options)?;
        let Probe::Duplicate(evidence) = first else {
            return Ok(first);
        };
        let mut seen = vec![evidence];
        let mut answered = 0;
        for _ in 0..options.confirm.saturating_mul(2) {
            match self.probe(id, options)? {
                Probe::Found(status) => return Ok(Probe::Found(status)),
                Probe::Duplicate(e) => {
                    seen.push(e);
                    answered += 1;
                    if answered >= options.confirm {
                        break;
                    }
                }
                Probe::Absent => {}
            }
        }
        let probes = seen.len();
        Ok(Probe::Duplicate(format!(
            "{probes} probe(s), none clean: {}",
            seen.join("; ")
        )))
    }

    /// One ID at the current rate.
    fn probe(&mut self, id: ServoId, options: &ScanOptions) -> Result<Probe, WckError> {
        let status_read = Command::StatusRead { id };
        let mut evidence: Vec<String> = Vec::new();
        let mut clean = None;
        for _ in 0..options.probes.max(1) {
            match self.scan_exchange(&status_read) {
                Ok(bytes) => {
                    clean = Some(bytes);
                    break;
                }
                Err(Failure::Timeout { received, .. }) if received.is_empty() => {}
                Err(Failure::Timeout { received, .. }) => {
                    self.settle();
                    evidence.push(format!(
                        "status read: only {} of 2 reply bytes ({})",
                        received.len(),
                        Hex(&received)
                    ));
                }
                Err(Failure::Link(source)) => return Err(self.link_error("scan", source)),
                // More than one answer, or bytes that came while no late window was open
                // and cannot be the reply (stray bytes before any module can have
                // answered): something answered, so the ID is never absent on them; it is
                // probed again.
                Err(Failure::Unattributable { bytes, anomaly }) => {
                    self.settle();
                    evidence.push(format!("status read: {}", anomaly.describe(&bytes, 2)));
                }
                Err(Failure::Bad { .. }) => self.settle(),
            }
        }
        let Some(bytes) = clean else {
            return Ok(if evidence.is_empty() {
                Probe::Absent
            } else {
                Probe::Duplicate(evidence.join("; "))
            });
        };
        let status = match status_read.decode_reply(&bytes) {
            Ok(Reply::Status { load, position }) => Some(Status { load, position }),
            Ok(_) => None,
            Err(e) => {
                evidence.push(format!(
                    "status read: implausible reply {} ({e})",
                    Hex(&bytes)
                ));
                None
            }
        };
        if options.check_duplicates {
            self.check_single(id, status, &mut evidence)?;
        }
        Ok(match (status, evidence.is_empty()) {
            (Some(status), true) => Probe::Found(status),
            _ => Probe::Duplicate(evidence.join("; ")),
        })
    }

    /// A status read of the scan. After a silent attempt the read is sent at once, without
    /// waiting out that attempt's late window (most IDs of a scan are silent: waiting
    /// would cost the whole window per probe). Nothing that comes back while the window is
    /// open is credited: it may be the late reply of the ID before. The window (of the
    /// earlier attempts and of this one) is then waited out, dropping everything, and the
    /// ID is asked again; only that answer counts. A late reply can so never be taken for
    /// the next ID's, as long as it comes within [`late_window`](super::WckConfig::late_window) of its
    /// deadline, the same bound every other transaction relies on.
    fn scan_exchange(&mut self, command: &Command) -> Result<[u8; 2], Failure> {
        if !self.late_reply_possible() {
            return self.exchange(command);
        }
        match self.exchange_now(command) {
            Err(Failure::Timeout { received, waited }) if received.is_empty() => {
                Err(Failure::Timeout { received, waited })
            }
            Err(Failure::Link(e)) => Err(Failure::Link(e)),
            _ => {
                // This attempt's own reply may still be on its way, too.
                self.expect_late();
                self.exchange(command)
            }
        }
    }

    /// The duplicate checks after a clean status reply.
    fn check_single(
        &mut self,
        id: ServoId,
        status: Option<Status>,
        evidence: &mut Vec<String>,
    ) -> Result<(), WckError> {
        let window = timing::wire_time(4, self.baud()) + Duration::from_millis(1);
        let extra = self.trailing_bytes(window)?;
        if extra > 0 {
            evidence.push(format!(
                "status read: {extra} extra byte(s) after the reply"
            ));
        }
        let read10 = Command::Read10 {
            id: ExtServoId::from(id),
        };
        if let Some(Reply::Position10(p10)) = self.probe_read(&read10, evidence)?
            && let Some(status) = status
        {
            let deg8 = status.position.degrees();
            let deg10 = p10.degrees();
            if (deg8 - deg10).abs() > POSITION_AGREEMENT_DEG {
                evidence.push(format!(
                    "8-bit position {} ({deg8:.1}°) and 10-bit position {} ({deg10:.1}°) disagree",
                    status.position,
                    Position10::get(p10)
                ));
            }
        }
        self.probe_read(&Command::IGainRead { id }, evidence)?;
        self.probe_read(&Command::OverloadRead { id }, evidence)?;
        Ok(())
    }

    /// One read during a duplicate check (a second try only if nothing came back);
    /// anything unclean is added to `evidence`.
    fn probe_read(
        &mut self,
        command: &Command,
        evidence: &mut Vec<String>,
    ) -> Result<Option<Reply>, WckError> {
        for _ in 0..2 {
            match self.exchange(command) {
                Ok(bytes) => {
                    return match command.decode_reply(&bytes) {
                        Ok(reply) => Ok(Some(reply)),
                        Err(e) => {
                            self.settle();
                            evidence.push(format!(
                                "{}: implausible reply {} ({e})",
                                command.name(),
                                Hex(&bytes)
                            ));
                            Ok(None)
                        }
                    };
                }
                Err(Failure::Timeout { received, .. }) if received.is_empty() => {}
                Err(Failure::Timeout { received, .. }) => {
                    self.settle();
                    evidence.push(format!(
                        "{}: only {} of 2 reply bytes ({})",
                        command.name(),
                        received.len(),
                        Hex(&received)
                    ));
                    return Ok(None);
                }
                Err(Failure::Link(source)) => return Err(self.link_error("scan", source)),
                Err(Failure::Unattributable {
                    bytes,
                    anomaly: anomaly @ Anomaly::Extra { .. },
                }) => {
                    self.settle();
                    evidence.push(format!(
                        "{}: {}",
                        command.name(),
                        anomaly.describe(&bytes, 2)
                    ));
                    return Ok(None);
                }
                Err(Failure::Bad { .. } | Failure::Unattributable { .. }) => {
                    self.settle();
                    return Ok(None);
                }
            }
        }
        evidence.push(format!(
            "{}: no reply, though the status read was answered",
            command.name()
        ));
        Ok(None)
    }
}
