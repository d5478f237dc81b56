//! Per-joint operations: status, enable, clear, set-id, scan, info, modes, zero, save, release-IAP, monitor samples.

use std::time::Duration;

use robobus_whj::error_code::ErrorCode;
use robobus_whj::units::CurrentScale;
use robobus_whj::{JointId, Request, WorkMode};
use serde::Serialize;

use crate::ops::{Control, DeviceResult, Failure, OpError, Progress};
use crate::whj::{Joint, JointBus, WhjError};

use super::{check_reading, mode_name, per_joint, whj};

// ---------------------------------------------------------------------------------------
// Status, enable, clear, set-id
// ---------------------------------------------------------------------------------------

/// One joint's status (`whj status`).
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct StatusReport {
    /// Drive enabled.
    pub enabled: bool,
    /// Work mode.
    pub mode: &'static str,
    /// Actual position, degrees.
    pub position_deg: f64,
    /// Actual current, mA (`None` in the 12-byte layout).
    pub current_ma: Option<i64>,
    /// Bus voltage, V.
    pub voltage_v: f64,
    /// Temperature, °C.
    pub temperature_c: f64,
    /// `locked` or `released`.
    pub brake: &'static str,
    /// Error bits.
    pub error: String,
}

/// Reads the status of one connected joint; an implausible reading ([`check_reading`]) is a
/// device failure naming it.
pub fn joint_status(j: &Joint<'_>) -> Result<StatusReport, OpError> {
    let st = j.status().map_err(whj)?;
    check_reading(j, st.position.degrees(), None)?;
    let mode = j.mode().map_err(whj)?;
    let scale = j
        .identity()
        .map_or(CurrentScale::OneMilliamp, |i| i.current_scale());
    Ok(StatusReport {
        enabled: st.is_enabled(),
        mode: mode_name(mode),
        position_deg: st.position.degrees(),
        current_ma: st.current.map(|c| c.milliamps(scale)),
        voltage_v: f64::from(st.voltage.volts()),
        temperature_c: f64::from(st.temperature.celsius()),
        brake: if st.brake_locked() {
            "locked"
        } else {
            "released"
        },
        error: st.error.to_string(),
    })
}

/// `whj status`: connects the joints (IAP releases pipelined, [`JointBus::joints`]) and
/// reads each one's status; a silent joint is a failed result, the others are still read.
pub fn status(bus: &JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, StatusReport>> {
    let mut joints = bus.joints(ids).into_iter();
    per_joint(ids, |_| {
        let j = joints
            .next()
            .unwrap_or(Err(WhjError::Closed))
            .map_err(whj)?;
        joint_status(&j)
    })
}

/// The state a joint reports after enable / disable.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct EnableReport {
    /// Drive enabled, as the joint reports it afterwards.
    pub enabled: bool,
    /// Error bits afterwards.
    pub error: String,
}

/// `whj enable` / `whj disable`: writes the enable register, then reads the state back; a
/// joint that stays in the wrong state, or reports error bits after an enable, is a failed
/// result naming the bits.
pub fn enable(bus: &JointBus, ids: &[JointId], on: bool) -> Vec<DeviceResult<u8, EnableReport>> {
    per_joint(ids, |id| {
        let j = bus.joint(id).map_err(whj)?;
        if on { j.enable() } else { j.disable() }.map_err(whj)?;
        let st = j.status().map_err(whj)?;
        if st.is_enabled() != on {
            return Err(OpError::Device(format!(
                "{id}: still {} after {} (error bits: {})",
                if on { "disabled" } else { "enabled" },
                if on { "enable" } else { "disable" },
                st.error
            )));
        }
        if on && !st.error.is_empty() {
            return Err(OpError::Device(format!(
                "{id}: enabled, but reports error bits: {} (clear them with `whj clear`)",
                st.error
            )));
        }
        Ok(EnableReport {
            enabled: st.is_enabled(),
            error: st.error.to_string(),
        })
    })
}

/// The error bits before and after `whj clear`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct ClearReport {
    /// Error bits before the clear.
    pub error_before: String,
    /// Error bits left afterwards (bits whose cause persists stay set).
    pub error_after: String,
}

/// `whj clear`: reads the error bits, clears, reads them again.
pub fn clear(bus: &JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, ClearReport>> {
    per_joint(ids, |id| {
        let j = bus.joint(id).map_err(whj)?;
        let before: ErrorCode = j.error_code().map_err(whj)?;
        let after = j.clear_error().map_err(whj)?;
        Ok(ClearReport {
            error_before: before.to_string(),
            error_after: after.to_string(),
        })
    })
}

/// Whether any joint answers at `id`: the IAP release (`IAP_FLAG := 0`), which a joint
/// answers in its bootloader and in its application, sent up to three times.
pub fn answers(bus: &JointBus, id: JointId) -> Result<bool, OpError> {
    for _ in 0..3 {
        match bus.request(Request::start_application(id)) {
            Ok(_) => return Ok(true),
            Err(e) if e.is_timeout() => {}
            Err(e) => return Err(whj(e)),
        }
    }
    Ok(false)
}

/// What `whj set-id` did.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct SetIdReport {
    /// The new ID.
    pub new_id: u8,
    /// `SYS_ID` as read back after the write.
    pub read_back: u8,
    /// The ID the read-back was answered at: the old one (the new ID applies after a power
    /// cycle), or the new one (firmware that applies it at once).
    pub answered_at: u8,
    /// Saved to flash.
    pub saved: bool,
    /// When it applies.
    pub note: &'static str,
}

/// The plan of `whj set-id`: the frames [`set_id`] sends (at the old ID; a joint whose
/// firmware applies the ID at once gets the read-back and the save at the new one) and
/// the note that says so.
pub fn plan_set_id(id: JointId, new_id: JointId) -> Result<(Vec<Request>, String), OpError> {
    let sys_id = robobus_whj::registers::addr::SYS_ID;
    let frames = vec![
        Request::enable(id, false),
        Request::write(id, sys_id, u16::from(new_id.get()))
            .map_err(|e| OpError::invalid("<NEW_ID>", new_id.get(), e.to_string()))?,
        Request::Read {
            joint: id,
            range: robobus_whj::ReadRange::new(sys_id, 1)
                .map_err(|e| OpError::invalid("<NEW_ID>", new_id.get(), e.to_string()))?,
        },
        Request::save_to_flash(id),
    ];
    let note = format!(
        "disable, write SYS_ID, read it back, save; the new ID {n} applies after a power cycle \
         (firmware V1.1 applies it at once: the read-back and the save then go to ID {n})",
        n = new_id.get()
    );
    Ok((frames, note))
}

/// `whj set-id`: refused while a joint answers at the new ID (two joints would share it
/// after the next power cycle); otherwise disable, write `SYS_ID`, save to flash.
pub fn set_id(bus: &JointBus, id: JointId, new_id: JointId) -> Result<SetIdReport, OpError> {
    if new_id == id {
        return Err(OpError::invalid(
            "set-id <NEW_ID>",
            new_id.get(),
            "the joint already has this ID",
        ));
    }
    check_id_free(bus, id, new_id)?;
    let j = bus.joint(id).map_err(whj)?;
    j.disable().map_err(whj)?;
    j.write_register_raw("SYS_ID", i32::from(new_id.get()))
        .map_err(whj)?;
    // Read back: at the old ID (the new one applies after a power cycle), or at the new
    // one where the firmware applies it at once.
    let (at, read_back) = match j.read_words(robobus_whj::registers::addr::SYS_ID, 1) {
        Ok(w) => (j, w),
        Err(e) if e.is_timeout() => {
            let k = bus.joint_unchecked(new_id);
            let w = k
                .read_words(robobus_whj::registers::addr::SYS_ID, 1)
                .map_err(whj)?;
            (k, w)
        }
        Err(e) => return Err(whj(e)),
    };
    let read_back = read_back.first().copied().unwrap_or(0);
    if read_back != u16::from(new_id.get()) {
        return Err(OpError::Device(format!(
            "set-id {} {}: SYS_ID reads back {read_back} at ID {}; the ID did not take (not \
             saved)",
            id.get(),
            new_id.get(),
            at.id().get()
        )));
    }
    at.save_to_flash().map_err(whj)?;
    Ok(SetIdReport {
        new_id: new_id.get(),
        read_back: u8::try_from(read_back).unwrap_or(u8::MAX),
        answered_at: at.id().get(),
        saved: true,
        note: "the new ID applies after a power cycle of the joint",
    })
}

/// Refuses an ID change of joint `id` to `new_id` while a joint answers at `new_id` (two
/// joints would share it after the next power cycle); nothing is sent to joint `id`.
pub fn check_id_free(bus: &JointBus, id: JointId, new_id: JointId) -> Result<(), OpError> {
    if answers(bus, new_id)? {
        return Err(OpError::Refused(format!(
            "set-id {} {}: a joint answers at ID {} already; after the next power cycle two \
             joints would share it. Give that joint another ID first; nothing was sent to \
             joint {}",
            id.get(),
            new_id.get(),
            new_id.get(),
            id.get()
        )));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Scan, info, modes, zero, save, release-IAP
// ---------------------------------------------------------------------------------------

/// A joint's identity (`whj scan`, `whj info`, `whj release-iap`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct IdentityReport {
    /// Model name.
    pub model: &'static str,
    /// Firmware version (four hex digits).
    pub firmware: String,
    /// Node ID register.
    pub node_id: u16,
    /// Gear reduction ratio.
    pub reduction: u16,
    /// 96-bit unique ID.
    pub unique_id: String,
}

impl IdentityReport {
    /// The report of an identity.
    pub fn of(i: &crate::whj::Identity) -> Self {
        Self {
            model: i.model.name(),
            firmware: i.firmware.to_string(),
            node_id: i.node_id,
            reduction: i.reduction_ratio,
            unique_id: i.unique_id.to_string(),
        }
    }
}

/// Two joints answering at one ID (two different unique IDs 0x2A..0x2F to one read).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct Duplicate {
    /// The shared ID.
    pub id: u8,
    /// The unique IDs that answered.
    pub unique_ids: [String; 2],
}

/// What `whj scan` found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScanReport {
    /// Joints that answered, in ID order.
    pub found: Vec<DeviceResult<u8, IdentityReport>>,
    /// IDs that more than one joint answers.
    pub duplicates: Vec<Duplicate>,
    /// IDs probed.
    pub probed: usize,
    /// Set when the scan was stopped before its last ID (`found` holds what it found
    /// until then): how far it got.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stopped: Option<String>,
}

/// Reads of the unique ID [`duplicates_of`] makes after the connect's own read.
const DUPLICATE_PROBES: usize = 3;

/// Whether more than one joint answers at `id` (already connected on `bus`): reads the
/// unique ID (0x2A..0x2F). Two joints at one ID both answer each read, the second within
/// the bus's collision window ([`JointBusConfig::collision_window`]), so the read fails
/// with [`WhjError::DuplicateReply`] and the bus records both unique IDs
/// ([`JointTelemetry::unique_id_conflict`]) on the first read already; the further reads
/// only matter without a collision window. `doctor` calls this too.
///
/// [`JointTelemetry::unique_id_conflict`]: crate::whj::JointTelemetry::unique_id_conflict
/// [`JointBusConfig::collision_window`]: crate::whj::JointBusConfig::collision_window
pub fn duplicates_of(bus: &JointBus, id: JointId) -> Option<Duplicate> {
    let j = bus.joint_unchecked(id);
    for _ in 0..DUPLICATE_PROBES {
        if bus.telemetry().joint(id).unique_id_conflict.is_some() {
            break;
        }
        let read = j.read_words(robobus_whj::registers::addr::MOT_MODEL_ID, 6);
        if matches!(read, Err(WhjError::DuplicateReply { .. })) {
            break;
        }
        if bus.duplicate_check().is_none() {
            // The second joint's reply comes after the first one's.
            bus.sleep_until(bus.now() + Duration::from_millis(5));
        }
    }
    conflict_of(bus, id)
}

/// The two unique IDs the bus has seen answer at `id`, if it saw two.
fn conflict_of(bus: &JointBus, id: JointId) -> Option<Duplicate> {
    bus.telemetry()
        .joint(id)
        .unique_id_conflict
        .map(|(a, b)| Duplicate {
            id: id.get(),
            unique_ids: [a.to_string(), b.to_string()],
        })
}

/// How long a scan waits for joints to answer their IAP release: a joint in its
/// bootloader answers at once, so an absent ID costs this, not the bus's connect timeout
/// (which allows for joints still powering up).
pub const SCAN_CONNECT_TIMEOUT: Duration = Duration::from_millis(150);

/// `whj scan`: connects every ID at once (IAP releases pipelined, then identify;
/// [`SCAN_CONNECT_TIMEOUT`] is what the absent IDs cost, once for all of them) and checks
/// each joint found for a second joint at its ID. IDs that stay silent are left out of
/// `found`; other failures are kept. Stopped by `control`, it returns what it found so
/// far with [`ScanReport::stopped`] set.
pub fn scan(
    bus: &JointBus,
    ids: &[JointId],
    control: &mut Control<'_>,
) -> Result<ScanReport, OpError> {
    let mut report = ScanReport {
        found: Vec::new(),
        duplicates: Vec::new(),
        probed: ids.len(),
        stopped: None,
    };
    let stopped_after = |k: usize| Some(format!("scan stopped after {k} of {} IDs", ids.len()));
    if control.stopped() {
        report.stopped = stopped_after(0);
        return Ok(report);
    }
    control.report(&Progress::new("scan", 0, Some(ids.len() as u64)).with_note("connecting"));
    let connected = bus.joints_within(ids, SCAN_CONNECT_TIMEOUT);
    for (k, (&id, joint)) in ids.iter().zip(connected).enumerate() {
        if control.stopped() {
            report.stopped = stopped_after(k);
            return Ok(report);
        }
        control.report(
            &Progress::new("scan", k as u64, Some(ids.len() as u64))
                .with_note(format!("J{}", id.get())),
        );
        match joint {
            Ok(j) => {
                let ident = j.identity().map_err(whj)?;
                report
                    .found
                    .push(DeviceResult::ok(id.get(), IdentityReport::of(&ident)));
                if let Some(d) = duplicates_of(bus, id) {
                    report.duplicates.push(d);
                }
            }
            Err(e) if e.is_timeout() => {}
            Err(e) => {
                // Two joints at the ID fail its connect with a duplicate reply: named in
                // the duplicates as well as in the joint's failure.
                if matches!(e, WhjError::DuplicateReply { .. })
                    && let Some(d) = conflict_of(bus, id).or_else(|| duplicates_of(bus, id))
                {
                    report.duplicates.push(d);
                }
                report
                    .found
                    .push(DeviceResult::failed(id.get(), Failure::from(&e)));
            }
        }
    }
    control.report(&Progress::new(
        "scan",
        ids.len() as u64,
        Some(ids.len() as u64),
    ));
    Ok(report)
}

/// `whj info`: identity, mode and position limits.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct InfoReport {
    /// Identity.
    #[serde(flatten)]
    pub identity: IdentityReport,
    /// Work mode.
    pub mode: &'static str,
    /// Lower position limit, degrees.
    pub min_deg: f64,
    /// Upper position limit, degrees.
    pub max_deg: f64,
}

/// `whj info` of one joint.
pub fn info(bus: &JointBus, id: JointId) -> Result<InfoReport, OpError> {
    let j = bus.joint(id).map_err(whj)?;
    let ident = j.identity().map_err(whj)?;
    let (min, max) = j.position_limits().map_err(whj)?;
    let mode = j.mode().map_err(whj)?;
    Ok(InfoReport {
        identity: IdentityReport::of(&ident),
        mode: mode_name(mode),
        min_deg: min.degrees(),
        max_deg: max.degrees(),
    })
}

/// The work mode a joint reports after `whj mode`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct ModeReport {
    /// Work mode read back.
    pub mode: &'static str,
}

/// `whj mode`: sets the mode, reads it back (a joint that reports another mode fails).
pub fn set_mode(
    bus: &JointBus,
    ids: &[JointId],
    mode: WorkMode,
) -> Vec<DeviceResult<u8, ModeReport>> {
    per_joint(ids, |id| {
        let j = bus.joint(id).map_err(whj)?;
        j.set_mode(mode).map_err(whj)?;
        let now = j.mode().map_err(whj)?;
        if now != mode {
            return Err(OpError::Device(format!(
                "{id}: reports {} mode after the change to {}",
                mode_name(now),
                mode_name(mode)
            )));
        }
        Ok(ModeReport {
            mode: mode_name(now),
        })
    })
}

/// The position after `whj zero`.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct ZeroReport {
    /// Position read after the zero, degrees.
    pub position_deg: f64,
}

/// `whj zero`: the present position becomes 0 deg.
pub fn zero(bus: &JointBus, id: JointId) -> Result<ZeroReport, OpError> {
    let j = bus.joint(id).map_err(whj)?;
    j.set_zero().map_err(whj)?;
    Ok(ZeroReport {
        position_deg: j.position().map_err(whj)?.degrees(),
    })
}

/// `whj save`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct SaveReport {
    /// Saved.
    pub saved: bool,
}

/// `whj save`: copies RAM to flash (refused while a joint is enabled).
pub fn save(bus: &JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, SaveReport>> {
    per_joint(ids, |id| {
        let j = bus.joint(id).map_err(whj)?;
        j.save_to_flash().map_err(whj)?;
        Ok(SaveReport { saved: true })
    })
}

/// `whj release-iap`: starts the application of joints in the bootloader.
pub fn release_iap(bus: &JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, IdentityReport>> {
    per_joint(ids, |id| {
        let j = bus.joint_unchecked(id);
        j.release_iap().map_err(whj)?;
        Ok(IdentityReport::of(&j.identity().map_err(whj)?))
    })
}

// ---------------------------------------------------------------------------------------
// Monitor sampling
// ---------------------------------------------------------------------------------------

/// One sample of one joint (`robobus monitor`): a status query and a speed read.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct JointSample {
    /// Actual position, degrees.
    pub position_deg: f64,
    /// Actual speed, RPM (`None` when the speed read failed).
    pub speed_rpm: Option<f64>,
    /// Actual current, mA (`None` in the 12-byte status layout).
    pub current_ma: Option<i64>,
    /// Drive enabled.
    pub enabled: bool,
    /// Error bits.
    pub error: String,
}

/// Samples joints once each, without the connect handshake (the bus caches identities, so
/// a sample costs two frames per joint). A joint that does not answer is a failed result:
/// the caller marks it missing, never shows older values as this sample's.
pub fn sample(bus: &JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, JointSample>> {
    per_joint(ids, |id| {
        let j = bus.joint_unchecked(id);
        let scale = j
            .identity()
            .map_or(CurrentScale::OneMilliamp, |i| i.current_scale());
        let st = j.status().map_err(whj)?;
        let speed_rpm = j.speed().ok().map(robobus_whj::units::ActualSpeed::rpm);
        check_reading(&j, st.position.degrees(), speed_rpm)?;
        Ok(JointSample {
            position_deg: st.position.degrees(),
            speed_rpm,
            current_ma: st.current.map(|c| c.milliamps(scale)),
            enabled: st.is_enabled(),
            error: st.error.to_string(),
        })
    })
}
