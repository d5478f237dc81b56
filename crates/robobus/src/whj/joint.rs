//! [`Joint`]: one WHJ joint on a [`JointBus`].

use core::time::Duration;
use std::sync::OnceLock;

use robobus_whj::registers::{self, Half, Persistence, RegisterInfo, UniqueId, Unit};
use robobus_whj::units::{
    ActualSpeed, CurrentScale, FirmwareVersion, Model, Position, TargetSpeed,
};
use robobus_whj::{
    ErrorCode, JointId, JointStatus, RegisterAddr, Reply, Request, ServoFeedback, WorkMode,
};

use super::bus::JointBus;
use super::error::{WhjError, attempt_error};
use super::identity::Identity;
use super::session::{Attempt, describe};
use super::trajectory::{MotionLimits, Profile};

mod owned;
mod servo;
pub use owned::OwnedJoint;

/// A register value read by name, with its unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegisterValue {
    /// The register (for a 32-bit pair: its low word).
    pub info: &'static RegisterInfo,
    /// The raw value (a pair combined into an i32; a single register as a signed 16-bit
    /// word, except raw/enum/flag registers which are shown unsigned).
    pub raw: i32,
    /// The value in engineering units (`unit`), where the register has a fixed scale.
    pub value: Option<f64>,
    /// The unit symbol of `value` ("°", "RPM", "mA", "V", ...; empty for unitless).
    pub unit: &'static str,
}

impl RegisterValue {
    /// The value of `info` from the words read at its address (a pair: low word first;
    /// missing words count as 0), converted with the joint's current scale.
    pub fn of(info: &'static RegisterInfo, words: &[u16], scale: CurrentScale) -> Self {
        let at = |i: usize| words.get(i).copied().unwrap_or(0);
        let raw = match info.half {
            Half::Low => registers::join_i32(at(0), at(1)),
            _ => info.word_value(at(0)),
        };
        let (value, unit) = unit_scale(info, scale);
        Self {
            info,
            raw,
            value: value.map(|s| f64::from(raw) * s),
            unit,
        }
    }
}

/// The scale (per count, [`Unit::per_count`]) and unit symbol of a register's value.
fn unit_scale(info: &RegisterInfo, scale: CurrentScale) -> (Option<f64>, &'static str) {
    let per_count = info.unit.per_count(scale);
    (per_count, per_count.map_or("", |_| info.unit.symbol()))
}

impl core::fmt::Display for RegisterValue {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.value {
            Some(v) => write!(
                f,
                "{} = {v} {} (raw {})",
                base_name(self.info),
                self.unit,
                self.raw
            ),
            None => write!(f, "{} = {}", base_name(self.info), self.raw),
        }
    }
}

/// The name of a register, without the `_L` suffix for a pair.
fn base_name(info: &RegisterInfo) -> &'static str {
    if info.half == Half::Low {
        info.name.strip_suffix("_L").unwrap_or(info.name)
    } else {
        info.name
    }
}

/// One WHJ joint on a [`JointBus`] (it borrows the bus, which owns the link).
///
/// Every method is one or a few request / reply exchanges. Reads, status queries,
/// servo set-points and writes of configuration values are retried
/// ([`JointBusConfig::retries`](super::JointBusConfig::retries)); set zero and save to
/// flash are sent once. Units: positions in 0.0001° ([`Position`]), target speed in 0.002
/// RPM ([`TargetSpeed`]), actual speed in 0.02 RPM ([`ActualSpeed`]), currents in 1 or 2
/// mA per count by model ([`Identity::current_scale`]).
#[derive(Debug)]
pub struct Joint<'a> {
    bus: &'a JointBus,
    id: JointId,
    identity: OnceLock<Identity>,
}

impl<'a> Joint<'a> {
    pub(crate) fn unchecked(bus: &'a JointBus, id: JointId) -> Self {
        Self {
            bus,
            id,
            identity: OnceLock::new(),
        }
    }

    pub(crate) fn connect(bus: &'a JointBus, id: JointId) -> Result<Self, WhjError> {
        let joint = Self::unchecked(bus, id);
        joint.release_iap()?;
        let identity = joint.identify()?;
        let _ = joint.identity.set(identity);
        bus.cache_identity(id, identity);
        Ok(joint)
    }

    /// The joint's bus ID.
    pub const fn id(&self) -> JointId {
        self.id
    }

    /// The bus this joint is on.
    pub const fn bus(&self) -> &'a JointBus {
        self.bus
    }

    /// Writes `IAP_FLAG := 0` (`02 49 00`, the vendor's "required operation") until the
    /// joint answers or [`JointBusConfig::connect_timeout`](super::JointBusConfig::connect_timeout)
    /// passes. Any answer counts: a joint already in its application acknowledges too.
    pub fn release_iap(&self) -> Result<(), WhjError> {
        release_iap_many(self.bus, &[self.id], self.bus.config().connect_timeout)
            .pop()
            .unwrap_or(Err(WhjError::Closed))
    }

    /// [`JointBus::joint`] for many joints at once: the IAP releases are pipelined (sent
    /// to every joint, then collected; repeated for the joints that did not answer until
    /// the connect timeout), then each joint that answered is identified. Results in `ids`
    /// order.
    pub(crate) fn connect_many(
        bus: &'a JointBus,
        ids: &[JointId],
        timeout: Duration,
    ) -> Vec<Result<Self, WhjError>> {
        release_iap_many(bus, ids, timeout)
            .into_iter()
            .zip(ids)
            .map(|(released, &id)| {
                released?;
                let joint = Self::unchecked(bus, id);
                let identity = joint.identify()?;
                let _ = joint.identity.set(identity);
                bus.cache_identity(id, identity);
                Ok(joint)
            })
            .collect()
    }

    /// The frames a connect sends ([`JointBus::joint`]), in order, as a dry run shows
    /// them: the IAP release (repeated until the joint answers, for at most the connect
    /// timeout), then the identity reads of [`Joint::identify`].
    pub fn connect_requests(id: JointId) -> Vec<Request> {
        let read = |addr, count| {
            robobus_whj::ReadRange::new(addr, count)
                .ok()
                .map(|range| Request::Read { joint: id, range })
        };
        core::iter::once(Some(Request::start_application(id)))
            .chain([
                read(registers::addr::SIGNATURE, 8),
                read(registers::addr::MOT_MODEL_ID, 6),
            ])
            .flatten()
            .collect()
    }

    /// Reads model, firmware version, node ID, gear ratio and unique ID.
    pub fn identify(&self) -> Result<Identity, WhjError> {
        let head = self.read_words(registers::addr::SIGNATURE, 8)?;
        let word = |i: usize| head.get(i).copied().unwrap_or(0);
        let uid = self.read_words(registers::addr::MOT_MODEL_ID, 6)?;
        let mut unique = [0u16; 6];
        for (slot, w) in unique.iter_mut().zip(&uid) {
            *slot = *w;
        }
        let identity = Identity {
            signature: word(0),
            node_id: word(1),
            model: Model::from_code(word(2)),
            firmware: FirmwareVersion(word(3)),
            reduction_ratio: word(7),
            unique_id: UniqueId(unique),
        };
        if identity.signature != registers::SIGNATURE_VALUE {
            tracing::warn!(joint = %self.id, signature = identity.signature, "unexpected signature register (0x1314 expected)");
        }
        Ok(identity)
    }

    /// The identity read at connect (or now, for a handle from
    /// [`JointBus::joint_unchecked`]).
    pub fn identity(&self) -> Result<Identity, WhjError> {
        if let Some(i) = self.identity.get() {
            return Ok(*i);
        }
        if let Some(i) = self.bus.cached_identity(self.id) {
            return Ok(*self.identity.get_or_init(|| i));
        }
        let i = self.identify()?;
        self.bus.cache_identity(self.id, i);
        Ok(*self.identity.get_or_init(|| i))
    }

    fn current_scale(&self) -> Result<CurrentScale, WhjError> {
        Ok(self.identity()?.current_scale())
    }

    /// Enables the drive (`SYS_ENABLE_DRIVER := 1`). In position mode the joint holds
    /// where it is. A joint with a latched error refuses: [`WhjError::EnableRefused`] with
    /// the error bits.
    pub fn enable(&self) -> Result<(), WhjError> {
        let reply = self.transact(Request::enable(self.id, true), true, Duration::ZERO)?;
        if matches!(reply, Reply::WriteAck { status, .. } if status.is_ok()) {
            return Ok(());
        }
        let code = self.status().map_or(ErrorCode::NONE, |s| s.error);
        Err(WhjError::EnableRefused {
            joint: self.id,
            code,
        })
    }

    /// Disables the drive (`SYS_ENABLE_DRIVER := 0`; brake models lock the brake). Nothing
    /// is sent to this joint for [`JointBusConfig::disable_settle`](super::JointBusConfig::disable_settle)
    /// (5 ms, §6.3) afterwards.
    pub fn disable(&self) -> Result<(), WhjError> {
        let settle = self.bus.config().disable_settle;
        let reply = self.transact(Request::enable(self.id, false), true, settle)?;
        self.check_ack(&reply, registers::addr::SYS_ENABLE_DRIVER, 0)
    }

    /// Whether the drive is enabled (register 0x0A).
    pub fn is_enabled(&self) -> Result<bool, WhjError> {
        Ok(self
            .read_words(registers::addr::SYS_ENABLE_DRIVER, 1)?
            .first()
            != Some(&0))
    }

    /// Sets the work mode (0x30). Change modes at standstill or while disabled.
    pub fn set_mode(&self, mode: WorkMode) -> Result<(), WhjError> {
        let reply = self.transact(Request::set_mode(self.id, mode), true, Duration::ZERO)?;
        self.check_ack(
            &reply,
            registers::addr::TAG_WORK_MODE,
            i32::from(mode.raw()),
        )
    }

    /// The work mode (0x30).
    pub fn mode(&self) -> Result<WorkMode, WhjError> {
        let w = self.read_words(registers::addr::TAG_WORK_MODE, 1)?;
        Ok(WorkMode::from_raw(w.first().copied().unwrap_or(0)))
    }

    /// Makes the present position 0° (0x0E := 1). Kept across power cycles only after
    /// [`Joint::save_to_flash`]. Sent once (not idempotent while moving).
    pub fn set_zero(&self) -> Result<(), WhjError> {
        let reply = self.transact(Request::set_zero(self.id), false, Duration::ZERO)?;
        self.check_ack(&reply, registers::addr::SYS_SET_ZERO_POS, 1)
    }

    /// Tries to clear latched errors (0x0F := 1) and returns the error bits still set
    /// afterwards (bits whose cause persists stay set). The joint stays disabled: set the
    /// mode and [`Joint::enable`] again (C8).
    pub fn clear_error(&self) -> Result<ErrorCode, WhjError> {
        let reply = self.transact(Request::clear_error(self.id), true, Duration::ZERO)?;
        self.check_ack(&reply, registers::addr::SYS_CLEAR_ERROR, 1)?;
        Ok(self.status()?.error)
    }

    /// The error bits (0x04).
    pub fn error_code(&self) -> Result<ErrorCode, WhjError> {
        let w = self.read_words(registers::addr::SYS_ERROR, 1)?;
        Ok(ErrorCode(w.first().copied().unwrap_or(0)))
    }

    /// Copies the RAM table to flash (0x0C := 1). Refused on the host while the joint is
    /// enabled ([`WhjError::SaveWhileEnabled`], the firmware saves only while disabled);
    /// nothing is sent to the joint for 50 ms afterwards (§6.4). Sent once.
    pub fn save_to_flash(&self) -> Result<(), WhjError> {
        if self.is_enabled()? {
            return Err(WhjError::SaveWhileEnabled { joint: self.id });
        }
        let settle = self.bus.config().save_settle;
        let reply = self.transact(Request::save_to_flash(self.id), false, settle)?;
        self.check_ack(&reply, registers::addr::SYS_SAVE_TO_FLASH, 1)
    }

    /// The position limits (0x44..=0x47) as (min, max).
    pub fn position_limits(&self) -> Result<(Position, Position), WhjError> {
        let w = self.read_words(registers::addr::LIT_MIN_POSITION, 4)?;
        let at = |i: usize| w.get(i).copied().unwrap_or(0);
        let limits = (
            Position(registers::join_i32(at(0), at(1))),
            Position(registers::join_i32(at(2), at(3))),
        );
        self.bus.cache_limits(self.id, limits);
        Ok(limits)
    }

    /// The position limits as this bus last read them ([`Joint::position_limits`]), read
    /// now if it has not, or if a frame that can write them went out since. For checking
    /// readings, where one more request per reading would cost the bus its rate.
    pub fn known_position_limits(&self) -> Result<(Position, Position), WhjError> {
        match self.bus.cached_limits(self.id) {
            Some(limits) => Ok(limits),
            None => self.position_limits(),
        }
    }

    /// Sets the position limits (each pair in one 4-byte write). Refused on the host
    /// (nothing sent) if `min > max`.
    pub fn set_position_limits(&self, min: Position, max: Position) -> Result<(), WhjError> {
        if min > max {
            return Err(WhjError::InvalidConfig {
                reason: format!(
                    "{}: position limit min {:.4}° is above max {:.4}°",
                    self.id,
                    min.degrees(),
                    max.degrees()
                ),
            });
        }
        self.write_i32(registers::addr::LIT_MIN_POSITION, min.raw())?;
        self.write_i32(registers::addr::LIT_MAX_POSITION, max.raw())
    }

    /// Reads a register by name (`"TAG_WORK_MODE"`, `"cur_position"` for a pair; ASCII
    /// case ignored) and converts it to its unit.
    pub fn read_register(&self, name: &str) -> Result<RegisterValue, WhjError> {
        let info = lookup(name)?;
        let count = if info.half == Half::Low { 2 } else { 1 };
        let w = self.read_words(info.addr, count)?;
        let scale = match info.unit {
            Unit::Current => self.current_scale()?,
            _ => CurrentScale::OneMilliamp,
        };
        Ok(RegisterValue::of(info, &w, scale))
    }

    /// Writes a register by name with a value in its unit (degrees for positions, RPM
    /// for speeds, mA for currents, V, °C, rpm/s, %), rounded to the nearest count.
    /// Registers without a fixed scale ([`RegisterValue::value`] is `None`) take raw
    /// values. Checked on the host against the register table (read-only, range, pair
    /// halves); nothing is sent if the check fails.
    pub fn write_register(&self, name: &str, value: f64) -> Result<(), WhjError> {
        let info = lookup(name)?;
        let (scale, _) = self.scale(info)?;
        let raw = value / scale.unwrap_or(1.0);
        let raw = raw.round();
        if !(f64::from(i32::MIN)..=f64::from(i32::MAX)).contains(&raw) {
            return Err(WhjError::Unit {
                joint: self.id,
                source: robobus_whj::units::UnitRangeError {
                    quantity: info.name,
                    value,
                    min: f64::from(i32::MIN) * scale.unwrap_or(1.0),
                    max: f64::from(i32::MAX) * scale.unwrap_or(1.0),
                },
            });
        }
        #[allow(clippy::cast_possible_truncation)] // checked to fit an i32 above
        self.write_register_raw(name, raw as i32)
    }

    /// Writes a register by name with a raw value (an i32 for a pair, else a 16-bit word:
    /// −32768..=65535, negative values sent as two's complement).
    pub fn write_register_raw(&self, name: &str, raw: i32) -> Result<(), WhjError> {
        let info = lookup(name)?;
        if info.half == Half::Low {
            return self.write_i32(info.addr, raw);
        }
        let word = if let Ok(w) = u16::try_from(raw) {
            w
        } else if let Ok(s) = i16::try_from(raw) {
            s.cast_unsigned()
        } else {
            return Err(WhjError::Request {
                joint: self.id,
                source: robobus_whj::RequestError::ValueOutOfRange {
                    addr: info.addr.get(),
                    name: info.name,
                    value: raw,
                    min: i32::from(i16::MIN),
                    max: i32::from(u16::MAX),
                },
            });
        };
        self.write_word(info.addr, word)
    }

    /// Writes one 16-bit register by address (checked against the table).
    pub fn write_word(&self, addr: RegisterAddr, value: u16) -> Result<(), WhjError> {
        let req = Request::write(self.id, addr, value).map_err(|source| WhjError::Request {
            joint: self.id,
            source,
        })?;
        let reply = self.transact(req, retry_write(addr), Duration::ZERO)?;
        self.check_ack(&reply, addr, i32::from(value))
    }

    /// Writes a 32-bit register pair in one frame (`addr` = its low word).
    pub fn write_i32(&self, addr: RegisterAddr, value: i32) -> Result<(), WhjError> {
        let req = Request::write_i32(self.id, addr, value).map_err(|source| WhjError::Request {
            joint: self.id,
            source,
        })?;
        let reply = self.transact(req, retry_write(addr), Duration::ZERO)?;
        self.check_ack(&reply, addr, value)
    }

    /// Reads `count` (1..=31) consecutive registers from `addr`, the padding dropped.
    /// With [`JointBusConfig::verify_reads`](super::JointBusConfig::verify_reads) the
    /// words are returned only once two reads agree.
    pub fn read_words(&self, addr: RegisterAddr, count: u8) -> Result<Vec<u16>, WhjError> {
        let req = Request::read(self.id, addr, count).map_err(|source| WhjError::Request {
            joint: self.id,
            source,
        })?;
        let cfg = self.bus.config();
        if !cfg.verify_reads {
            return self.read_once(req, addr, count);
        }
        let max = 2 + 2 * cfg.retries;
        let mut previous: Option<Vec<u16>> = None;
        for _ in 0..max {
            let words = self.read_once(req, addr, count)?;
            if previous.as_ref() == Some(&words) {
                return Ok(words);
            }
            previous = Some(words);
        }
        Err(WhjError::Unverified {
            joint: self.id,
            register: RegisterInfo::by_addr(addr).map_or("reserved", |i| i.name),
            addr: addr.get(),
            attempts: max,
        })
    }

    fn read_once(&self, req: Request, addr: RegisterAddr, count: u8) -> Result<Vec<u16>, WhjError> {
        match self.transact(req, true, Duration::ZERO)? {
            Reply::Read { words, .. } => {
                Ok(words.truncated(usize::from(count)).as_slice().to_vec())
            }
            other => Err(WhjError::BadReply {
                joint: self.id,
                request: describe(&req),
                reason: format!(
                    "expected a read reply for {:#04x}, got {other:?}",
                    addr.get()
                ),
                attempts: 1,
            }),
        }
    }

    /// The actual position (0x14/0x15).
    pub fn position(&self) -> Result<Position, WhjError> {
        let w = self.read_words(registers::addr::CUR_POSITION, 2)?;
        let at = |i: usize| w.get(i).copied().unwrap_or(0);
        Ok(Position(registers::join_i32(at(0), at(1))))
    }

    /// The actual speed (0x12/0x13, 0.02 RPM counts).
    pub fn speed(&self) -> Result<ActualSpeed, WhjError> {
        let w = self.read_words(registers::addr::CUR_SPEED, 2)?;
        let at = |i: usize| w.get(i).copied().unwrap_or(0);
        Ok(ActualSpeed(registers::join_i32(at(0), at(1))))
    }

    /// Queries the status frame (`0x600+ID` → `0x700+ID`): error bits, voltage,
    /// temperature, enable, brake, position, current.
    pub fn status(&self) -> Result<JointStatus, WhjError> {
        match self.transact(
            Request::StatusQuery { joint: self.id },
            true,
            Duration::ZERO,
        )? {
            Reply::Status { status, .. } => Ok(status),
            other => Err(self.unexpected(Request::StatusQuery { joint: self.id }, &other)),
        }
    }

    /// Sends one position servo frame (`0x200+ID`, acts in position mode) and returns the
    /// feedback (position *before* the command). Refused on the host
    /// ([`WhjError::StepTooLarge`]) if the target is further than
    /// [`JointBusConfig::step_limit_deg`](super::JointBusConfig::step_limit_deg) from the
    /// actual position (from the latest telemetry, or a status query if that is older
    /// than 100 ms); use [`Joint::move_to`] for large moves.
    pub fn command_position(&self, target: Position) -> Result<ServoFeedback, WhjError> {
        self.servo(Request::PositionServo {
            joint: self.id,
            target,
        })
    }

    /// Sends one speed servo frame (`0x300+ID`, 0.002 RPM counts; acts in speed mode).
    pub fn command_speed(&self, target: TargetSpeed) -> Result<ServoFeedback, WhjError> {
        self.servo(Request::SpeedServo {
            joint: self.id,
            target,
        })
    }

    /// Sends one current servo frame (`0x400+ID`; acts in current mode). `milliamps` is
    /// converted with the model's current LSB (1 or 2 mA).
    pub fn command_current(&self, milliamps: f64) -> Result<ServoFeedback, WhjError> {
        let target = robobus_whj::units::Current::from_milliamps(milliamps, self.current_scale()?)
            .map_err(|source| WhjError::Unit {
                joint: self.id,
                source,
            })?;
        self.servo(Request::CurrentServo {
            joint: self.id,
            target,
        })
    }

    /// Sends one servo frame of a plan (position, speed or current, for this joint) and
    /// returns its feedback. A position target further than the step limit from the actual
    /// position is refused on the host ([`WhjError::StepTooLarge`]), as in
    /// [`Joint::command_position`]; any other request is [`WhjError::InvalidConfig`].
    pub fn servo_request(&self, request: Request) -> Result<ServoFeedback, WhjError> {
        match request {
            Request::PositionServo { joint, .. }
            | Request::SpeedServo { joint, .. }
            | Request::CurrentServo { joint, .. }
                if joint == self.id =>
            {
                self.servo(request)
            }
            other => Err(WhjError::InvalidConfig {
                reason: format!("{}: not a servo frame for this joint: {other:?}", self.id),
            }),
        }
    }

    /// Sends one servo frame of a plan whose steps were checked before its first frame
    /// (`ops::whj::check_plan_steps`) and returns its feedback. Unlike
    /// [`Joint::servo_request`] it does not measure a position target against the last
    /// feedback, which lags the plan by a frame or two: a checked plan is sent as planned,
    /// and the caller watches the feedback. The frame is sent once, never retried. Any request but this joint's servo frames is
    /// [`WhjError::InvalidConfig`].
    pub fn send_planned(&self, request: Request) -> Result<ServoFeedback, WhjError> {
        match request {
            Request::PositionServo { joint, .. }
            | Request::SpeedServo { joint, .. }
            | Request::CurrentServo { joint, .. }
                if joint == self.id =>
            {
                // Sent once: the plan's next frame follows in one period, and a resent
                // frame would go out of its time.
                match self.transact(request, false, Duration::ZERO)? {
                    Reply::ServoFeedback { feedback, .. } => Ok(feedback),
                    other => Err(self.unexpected(request, &other)),
                }
            }
            other => Err(WhjError::InvalidConfig {
                reason: format!("{}: not a servo frame for this joint: {other:?}", self.id),
            }),
        }
    }

    /// Moves to `target` along a smooth speed / acceleration-limited profile, streaming
    /// position servo frames every `limits.period`, so no step exceeds the joint's 10°
    /// protection; then waits (status queries) until the actual position is within
    /// `limits.tolerance_deg` of the target, and returns that fresh status. The set-points
    /// are [`Profile::plan`]'s, the same plan `robobus whj move` shows and runs.
    /// [`WhjError::MoveIncomplete`] if the joint is not there `limits.settle_timeout` after
    /// the profile ended. The joint must be enabled in position mode.
    pub fn move_to(&self, target: Position, limits: MotionLimits) -> Result<JointStatus, WhjError> {
        limits
            .validate()
            .map_err(|reason| WhjError::InvalidConfig { reason })?;
        let start_pos = self.status()?.position;
        let goal = target.degrees();
        let points =
            Profile::plan(start_pos.degrees(), goal, limits, 10_000_000).ok_or_else(|| {
                WhjError::InvalidConfig {
                    reason: format!("{}: move to {goal} deg needs too many set-points", self.id),
                }
            })?;
        let started = self.bus.now();
        let mut next = started;
        for cmd in points {
            let setpoint = Position::from_degrees(cmd).map_err(|source| WhjError::Unit {
                joint: self.id,
                source,
            })?;
            self.command_position(setpoint)?;
            next += limits.period;
            self.bus.sleep_until(next);
        }
        let settle = self.bus.now();
        loop {
            let st = self.status()?;
            if (st.position.degrees() - goal).abs() <= limits.tolerance_deg {
                return Ok(st);
            }
            let now = self.bus.now();
            if now.saturating_duration_since(settle) > limits.settle_timeout {
                return Err(WhjError::MoveIncomplete {
                    joint: self.id,
                    target_deg: goal,
                    actual_deg: st.position.degrees(),
                    waited: now.saturating_duration_since(started),
                    code: st.error,
                });
            }
            self.bus.sleep_until(now + limits.period);
        }
    }

    pub(crate) fn recent_position(&self) -> Result<Position, WhjError> {
        self.recent_position_in(&self.bus.telemetry())
    }

    /// [`Joint::recent_position`] from a snapshot of the bus's telemetry.
    pub(crate) fn recent_position_in(
        &self,
        telemetry: &super::BusTelemetry,
    ) -> Result<Position, WhjError> {
        let t = *telemetry.joint(self.id);
        if let (Some(p), Some(at)) = (t.position, t.updated)
            && self.bus.now().saturating_duration_since(at) < Duration::from_millis(100)
        {
            return Ok(p);
        }
        Ok(self.status()?.position)
    }

    /// One servo frame of this joint's ([`JointBus::servo_many`] of one).
    fn servo(&self, req: Request) -> Result<ServoFeedback, WhjError> {
        self.bus
            .servo_many(&[req])?
            .pop()
            .unwrap_or_else(|| Err(self.bus.closed_error()))
    }

    fn unexpected(&self, req: Request, got: &Reply) -> WhjError {
        WhjError::BadReply {
            joint: self.id,
            request: describe(&req),
            reason: format!("unexpected reply {got:?}"),
            attempts: 1,
        }
    }

    fn scale(&self, info: &RegisterInfo) -> Result<(Option<f64>, &'static str), WhjError> {
        let scale = match info.unit {
            Unit::Current => self.current_scale()?,
            _ => CurrentScale::OneMilliamp,
        };
        Ok(unit_scale(info, scale))
    }

    fn check_ack(&self, reply: &Reply, addr: RegisterAddr, value: i32) -> Result<(), WhjError> {
        match reply {
            Reply::WriteAck { status, .. } if status.is_ok() => Ok(()),
            Reply::WriteAck { .. } => Err(WhjError::WriteRefused {
                joint: self.id,
                register: RegisterInfo::by_addr(addr).map_or("reserved", |i| i.name),
                addr: addr.get(),
                value,
            }),
            other => Err(WhjError::BadReply {
                joint: self.id,
                request: format!("write to {:#04x}", addr.get()),
                reason: format!("expected a write ack, got {other:?}"),
                attempts: 1,
            }),
        }
    }

    /// One request with the retry policy: `retry` for reads and idempotent operations
    /// (the session sends it again, [`JointBusConfig::retries`](super::JointBusConfig::retries)
    /// times at most, after a timeout, a malformed reply, a bus error, or a `CMD_ERR`
    /// format error or undefined error code). `CMD_ERR` replies become
    /// [`WhjError::CmdErr`].
    fn transact(
        &self,
        request: Request,
        retry: bool,
        quiet_after: Duration,
    ) -> Result<Reply, WhjError> {
        let cfg = self.bus.config();
        let attempts = if retry {
            cfg.retries.saturating_add(1)
        } else {
            1
        };
        let outcome = self
            .bus
            .transact(request, cfg.reply_timeout, quiet_after, attempts)?;
        match outcome.attempt {
            Attempt::Reply { reply } if !matches!(reply, Reply::CmdErr { .. }) => Ok(reply),
            last => Err(attempt_error(self.id, &request, last, outcome.attempts)),
        }
    }
}

/// Writes `IAP_FLAG := 0` to every joint of `ids` at once, then again to those that did
/// not answer, until all answered or the connect timeout passed (see
/// [`Joint::release_iap`]). Results in `ids` order.
fn release_iap_many(
    bus: &JointBus,
    ids: &[JointId],
    timeout: Duration,
) -> Vec<Result<(), WhjError>> {
    let cfg = bus.config();
    let start = bus.now();
    let mut results: Vec<Option<Result<(), WhjError>>> = ids.iter().map(|_| None).collect();
    let mut attempts = vec![0u32; ids.len()];
    let mut pending: Vec<usize> = (0..ids.len()).collect();
    while !pending.is_empty() {
        let requests: Vec<Request> = pending
            .iter()
            .filter_map(|&i| ids.get(i).map(|id| Request::start_application(*id)))
            .collect();
        let outcomes = match bus.attempt_many(&requests, cfg.reply_timeout) {
            Ok(o) => o,
            Err(e) => {
                let detail = e.to_string();
                for &i in &pending {
                    results[i] = Some(Err(WhjError::Link {
                        detail: detail.clone(),
                    }));
                }
                break;
            }
        };
        let mut again = Vec::new();
        for ((&i, outcome), req) in pending.iter().zip(outcomes).zip(&requests) {
            attempts[i] += 1;
            let id = ids[i];
            match outcome {
                Err(e) => results[i] = Some(Err(e)),
                Ok(Attempt::Reply { reply }) => {
                    if !matches!(reply, Reply::WriteAck { status, .. } if status.is_ok()) {
                        tracing::warn!(joint = %id, ?reply, "IAP release not acknowledged with success; continuing");
                    }
                    results[i] = Some(Ok(()));
                }
                Ok(a @ (Attempt::Link(_) | Attempt::Busy | Attempt::Duplicate { .. })) => {
                    results[i] = Some(Err(attempt_error(id, req, a, attempts[i])));
                }
                Ok(
                    Attempt::Mismatch(_)
                    | Attempt::Timeout { .. }
                    | Attempt::Bus { .. }
                    | Attempt::Late { .. },
                ) => {
                    again.push(i);
                }
            }
        }
        pending = again;
        if pending.is_empty() {
            break;
        }
        let now = bus.now();
        let waited = now.saturating_duration_since(start);
        if waited >= timeout {
            for &i in &pending {
                results[i] = Some(Err(WhjError::Silent {
                    joint: ids[i],
                    waited,
                    attempts: attempts[i],
                }));
            }
            break;
        }
        bus.sleep_until(now + Duration::from_millis(5));
    }
    results
        .into_iter()
        .map(|r| r.unwrap_or(Err(WhjError::Closed)))
        .collect()
}

/// Whether a write to `addr` may be resent: every write except the self-clearing
/// triggers (save, zero, calibration), whose repetition is not harmless.
fn retry_write(addr: RegisterAddr) -> bool {
    RegisterInfo::by_addr(addr).is_none_or(|i| i.persistence != Persistence::Trigger)
        || addr == registers::addr::SYS_CLEAR_ERROR
}

fn lookup(name: &str) -> Result<&'static RegisterInfo, WhjError> {
    RegisterInfo::by_name(name).ok_or_else(|| WhjError::UnknownRegister { name: name.into() })
}
