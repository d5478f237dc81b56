//! The checks that talk to devices (only when asked: `--wck-port`, `--whj-bus`): servos
//! and joints that are silent, joints waiting in their bootloader (IAP), two devices
//! sharing an ID, and WHJ firmware that lacks a feature robobus uses.

use std::time::Duration;

use robobus::wck::{ScanOptions, WckBus};
use robobus::whj::{JointBus, WhjError};
use robobus_link::ByteLink;
use robobus_whj::{FIRMWARE_GATES, JointId, Reply, Request};

use super::{Finding, Status, finding};

/// How long a joint is given to answer a status query before it counts as not running.
const STATUS_WAIT: Duration = Duration::from_millis(50);

/// How long after a status reply further replies from the same ID are counted (a second
/// joint with the ID answers within a frame time or two).
const DUPLICATE_WINDOW: Duration = Duration::from_millis(30);

/// Probes WHJ joints `ids` on `bus`: running or in the bootloader (released if so), one
/// joint per ID, firmware gates. `bus_name` names the bus in the findings.
pub(crate) fn whj(bus: &JointBus, bus_name: &str, ids: &[u8]) -> Vec<Finding> {
    let mut out = Vec::new();
    for &raw in ids {
        let Ok(id) = JointId::new(raw) else {
            continue;
        };
        let subject = format!("J{raw} on {bus_name}");
        let before = Counts::now(bus, id);
        let status = bus.request_with_timeout(Request::StatusQuery { joint: id }, STATUS_WAIT);
        match status {
            Ok(Reply::Status { .. }) => out.push(finding(
                &subject,
                "iap",
                Status::Ok,
                "running its application (answers status queries)",
                None,
            )),
            Ok(other) => out.push(finding(
                &subject,
                "iap",
                Status::Fail,
                format!("answered a status query with {other:?}"),
                Some("check that nothing else on the bus uses this ID".into()),
            )),
            Err(e) if e.is_timeout() => match bus.joint_unchecked(id).release_iap() {
                Ok(()) => out.push(finding(
                    &subject,
                    "iap",
                    Status::Warn,
                    "was waiting in its bootloader (IAP): it answered only the IAP release, \
                     which started its application now",
                    Some(
                        "after every power-up a program must write IAP_FLAG (0x49) := 0 before \
                         anything else (robobus does on connect; robobus whj release-iap)"
                            .into(),
                    ),
                )),
                Err(e) => {
                    out.push(finding(
                        &subject,
                        "iap",
                        Status::Fail,
                        format!("silent: {e}"),
                        Some(
                            "check power, the CAN wiring and its 120 Ω terminations, the bit \
                             rates (1 Mbit/s arbitration, 5 Mbit/s data) and the ID (robobus \
                             whj scan)"
                                .into(),
                        ),
                    ));
                    continue;
                }
            },
            Err(e) => {
                out.push(finding(&subject, "iap", Status::Fail, e.to_string(), None));
                continue;
            }
        }
        out.push(duplicate(bus, id, &subject, before));
        out.push(firmware(bus, id, &subject));
    }
    out
}

/// The replies from one ID and the frames sent on the bus so far: the probe of one ID
/// runs alone on its bus, so every frame sent meanwhile went to that ID, and one joint
/// answers each at most once (a reply that came after its request timed out included).
#[derive(Debug, Clone, Copy)]
struct Counts {
    replies: u64,
    sent: u64,
}

impl Counts {
    fn now(bus: &JointBus, id: JointId) -> Self {
        let t = bus.telemetry();
        Self {
            replies: t.joint(id).replies,
            sent: t.bus.frames_sent,
        }
    }
}

/// Two joints at one ID: two differing unique IDs (0x2A..0x2F) in the answers to the
/// library's identity probes ([`robobus::ops::whj::duplicates_of`], what `whj scan` uses),
/// or more replies than requests sent to it.
fn duplicate(bus: &JointBus, id: JointId, subject: &str, before: Counts) -> Finding {
    let fix = || {
        Some(format!(
            "connect the joints one at a time and give each its own ID (robobus whj \
             --bus BUS set-id {} NEW, then save)",
            id.get()
        ))
    };
    for _ in 0..2 {
        // Two different answers to one query, within the bus's collision window; any
        // other outcome is counted below.
        if let Err(robobus::whj::WhjError::DuplicateReply { first, second, .. }) =
            bus.request_with_timeout(Request::StatusQuery { joint: id }, STATUS_WAIT)
        {
            return finding(
                subject,
                "duplicate-id",
                Status::Fail,
                format!(
                    "two different replies to one status query ({first} and {second}): \
                     more than one joint answers as ID {}",
                    id.get()
                ),
                fix(),
            );
        }
    }
    std::thread::sleep(DUPLICATE_WINDOW);
    // Every request counts, answered in time or not: a loaded host may see an answer
    // after its request timed out, and that is one joint answering late, not two.
    let after = Counts::now(bus, id);
    let replies = after.replies.saturating_sub(before.replies);
    let sent = after.sent.saturating_sub(before.sent);
    if replies > sent {
        finding(
            subject,
            "duplicate-id",
            Status::Fail,
            format!(
                "{replies} replies to {sent} requests: more than one joint answers as ID {}",
                id.get()
            ),
            fix(),
        )
    } else if let Some(d) = robobus::ops::whj::duplicates_of(bus, id) {
        // Checked after the count: its identity probes add replies of their own.
        finding(
            subject,
            "duplicate-id",
            Status::Fail,
            format!(
                "two joints answer as ID {}: unique IDs {} and {}",
                d.id, d.unique_ids[0], d.unique_ids[1]
            ),
            fix(),
        )
    } else {
        finding(
            subject,
            "duplicate-id",
            Status::Ok,
            "one joint answers",
            None,
        )
    }
}

fn firmware(bus: &JointBus, id: JointId, subject: &str) -> Finding {
    let identity = match bus.joint_unchecked(id).identity() {
        Ok(i) => i,
        Err(e) => {
            return finding(
                subject,
                "firmware",
                Status::Warn,
                format!("identity not readable: {}", short(&e)),
                None,
            );
        }
    };
    let v = identity.firmware;
    // The register table's gates, for the features this joint's model can have at all.
    let missing: Vec<String> = FIRMWARE_GATES
        .iter()
        .filter(|g| identity.model.may_have(g.feature) && !g.admits(v))
        .map(|g| format!("{} (needs {})", g.what, g.label))
        .collect();
    if missing.is_empty() {
        finding(
            subject,
            "firmware",
            Status::Ok,
            format!(
                "{} firmware {:04X}: every documented feature gate passes",
                identity.model.name(),
                v.0
            ),
            None,
        )
    } else {
        finding(
            subject,
            "firmware",
            Status::Warn,
            format!(
                "{} firmware {:04X} lacks: {}",
                identity.model.name(),
                v.0,
                missing.join("; ")
            ),
            Some(
                "avoid those features on this joint, or update its firmware (the vendor's \
                 tool); the gates follow the vendor's labels, whose mapping to the register \
                 is inferred"
                    .into(),
            ),
        )
    }
}

fn short(e: &WhjError) -> String {
    e.to_string().lines().next().unwrap_or_default().to_owned()
}

/// Scans the wCK bus at its rate: servos found, IDs shared by two modules.
pub(crate) fn wck<L: ByteLink>(bus: &mut WckBus<L>, port: &str) -> Vec<Finding> {
    let baud = bus.baud();
    let report = match bus.scan(&ScanOptions::default(), |_| {}) {
        Ok(r) => r,
        Err(e) => {
            return vec![finding(port, "servos", Status::Fail, e.to_string(), None)];
        }
    };
    let mut out = Vec::new();
    if report.found.is_empty() && report.duplicates.is_empty() {
        out.push(finding(
            port,
            "servos",
            Status::Fail,
            format!("no servo answered at {baud} (IDs 0..=30)"),
            Some(format!(
                "check power and wiring, then look at every rate: robobus wck --port {port} \
                 scan --all-bauds"
            )),
        ));
    } else {
        let ids: Vec<String> = report
            .found
            .iter()
            .map(|f| f.id.get().to_string())
            .collect();
        out.push(finding(
            port,
            "servos",
            Status::Ok,
            format!(
                "{} servo(s) at {baud}: IDs {}",
                report.found.len(),
                if ids.is_empty() {
                    "none alone".to_owned()
                } else {
                    ids.join(", ")
                }
            ),
            None,
        ));
    }
    for d in &report.duplicates {
        out.push(finding(
            port,
            "duplicate-id",
            Status::Fail,
            format!(
                "ID {} is answered by more than one module: {}",
                d.id.get(),
                d.evidence
            ),
            Some(format!(
                "connect the modules with ID {id} one at a time and give each its own ID: \
                 robobus wck --port {port} set-id {id} NEW",
                id = d.id.get()
            )),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use robobus_sim::wck::{Bus, BusConfig, Eeprom, Model, SimLink};
    use robobus_sim::whj::{JointConfig, WhjBus, WhjModel};
    use robobus_wck::{BaudRate, ExtServoId};
    use robobus_whj::units::FirmwareVersion;

    fn status_of<'a>(findings: &'a [Finding], subject: &str, check: &str) -> &'a Finding {
        findings
            .iter()
            .find(|f| f.subject.starts_with(subject) && f.check == check)
            .unwrap_or_else(|| panic!("no {check} finding for {subject}: {findings:#?}"))
    }

    #[test]
    fn wck_probe_reports_servos_and_a_shared_id() {
        let mut sim = Bus::new(BusConfig::default());
        for id in [0u8, 3, 3] {
            let eeprom = Eeprom {
                id: ExtServoId::new(id).unwrap(),
                ..Eeprom::default()
            };
            sim.add(Model::W1108, eeprom, 100.0 + f64::from(id) * 10.0);
        }
        sim.servo_mut(2).unwrap().set_position(200);
        let (link, handle) = SimLink::new(sim);
        std::thread::sleep(Duration::from_millis(70).saturating_sub(handle.now()));
        let mut bus = WckBus::new(link, BaudRate::B115200).unwrap();
        let f = wck(&mut bus, "/dev/ttyUSB0");
        let servos = status_of(&f, "/dev/ttyUSB0", "servos");
        assert_eq!(servos.status, Status::Ok, "{f:#?}");
        assert!(servos.detail.contains("IDs 0"), "{f:#?}");
        let dup = status_of(&f, "/dev/ttyUSB0", "duplicate-id");
        assert_eq!(dup.status, Status::Fail, "{f:#?}");
        assert!(dup.detail.contains("ID 3"), "{f:#?}");
        assert!(dup.fix.as_deref().unwrap().contains("set-id 3"), "{f:#?}");
    }

    #[test]
    fn wck_probe_of_a_silent_bus_fails_and_suggests_every_rate() {
        let (link, _handle) = SimLink::new(Bus::new(BusConfig::default()));
        let mut bus = WckBus::new(link, BaudRate::B115200).unwrap();
        let f = wck(&mut bus, "P");
        assert_eq!(f.len(), 1, "{f:#?}");
        assert_eq!(f[0].status, Status::Fail);
        assert!(
            f[0].fix.as_deref().unwrap().contains("--all-bauds"),
            "{f:#?}"
        );
    }

    /// Runs `f` on a client bus to simulated joints `configs`, served on a thread.
    fn with_whj_bus<R>(configs: Vec<JointConfig>, f: impl FnOnce(&JointBus) -> R) -> R {
        let wire = robobus_link::MemoryBus::new();
        let server = robobus_sim::whj::Served::spawn(
            "sim-whj",
            WhjBus::with_configs(configs, 11),
            wire.endpoint(),
        )
        .unwrap();
        // A silent joint gives up after 0.5 s.
        let config = robobus::whj::JointBusConfig {
            connect_timeout: Duration::from_millis(500),
            ..robobus::whj::JointBusConfig::simulated()
        };
        let bus = JointBus::open_with(wire.endpoint(), config).unwrap();
        let out = f(&bus);
        drop(bus);
        server.stop().unwrap();
        out
    }

    #[test]
    fn whj_probe_finds_running_iap_silent_and_old_firmware() {
        // J1 still in its bootloader (as shipped), J2 already running with old firmware.
        let j1 = JointConfig::new(1, WhjModel::Whj30);
        let mut j2 = JointConfig::new(2, WhjModel::Whj30);
        j2.firmware = FirmwareVersion(0xD505);
        let f = with_whj_bus(vec![j1, j2], |bus| {
            // J2 running: release it first, as a program would have.
            bus.joint_unchecked(JointId::new(2).unwrap())
                .release_iap()
                .unwrap();
            whj(bus, "mem", &[1, 2, 3])
        });

        assert_eq!(status_of(&f, "J1 ", "iap").status, Status::Warn, "{f:#?}");
        assert_eq!(
            status_of(&f, "J1 ", "firmware").status,
            Status::Ok,
            "{f:#?}"
        );
        assert_eq!(
            status_of(&f, "J1 ", "duplicate-id").status,
            Status::Ok,
            "{f:#?}"
        );
        assert_eq!(status_of(&f, "J2 ", "iap").status, Status::Ok, "{f:#?}");
        let fw = status_of(&f, "J2 ", "firmware");
        assert_eq!(fw.status, Status::Warn, "{f:#?}");
        assert!(
            fw.detail.contains("D505") && fw.detail.contains("519"),
            "{f:#?}"
        );
        assert!(!fw.detail.contains("broadcast"), "{f:#?}");
        let j3 = status_of(&f, "J3 ", "iap");
        assert_eq!(j3.status, Status::Fail, "{f:#?}");
        assert!(j3.detail.contains("silent"), "{f:#?}");
    }

    #[test]
    fn whj_firmware_gates_come_from_the_register_table_and_the_model() {
        // A WHJ120 has neither low-power mode nor the direct brake release, whatever its
        // firmware: only the gates its model can have are reported.
        let mut j5 = JointConfig::new(5, WhjModel::Whj120);
        j5.firmware = FirmwareVersion(0xD505);
        let f = with_whj_bus(vec![j5], |bus| {
            bus.joint_unchecked(JointId::new(5).unwrap())
                .release_iap()
                .unwrap();
            whj(bus, "mem", &[5])
        });
        let fw = status_of(&f, "J5 ", "firmware");
        assert_eq!(fw.status, Status::Warn, "{f:#?}");
        assert_eq!(
            fw.detail,
            "WHJ120 firmware D505 lacks: staggered power-up switch 0x1F (needs 519); \
             end-board mode 0x79 (needs 519)"
        );
    }

    #[test]
    fn whj_probe_finds_two_joints_sharing_an_id() {
        let configs = vec![
            JointConfig::new(4, WhjModel::Whj30),
            JointConfig::new(4, WhjModel::Whj30),
        ];
        let f = with_whj_bus(configs, |bus| whj(bus, "mem", &[4]));
        let dup = status_of(&f, "J4 ", "duplicate-id");
        assert_eq!(dup.status, Status::Fail, "{f:#?}");
        assert!(dup.fix.as_deref().unwrap().contains("set-id 4"), "{f:#?}");
    }

    /// A joint that answers after the probe's status queries timed out (what a loaded host
    /// or a slow adapter makes of a running joint) answers each request once: one joint,
    /// not two.
    #[test]
    fn whj_probe_takes_a_joint_answering_late_for_one_joint() {
        let mut slow = JointConfig::new(6, WhjModel::Whj30);
        slow.processing_delay = STATUS_WAIT + Duration::from_millis(20);
        let f = with_whj_bus(vec![slow], |bus| whj(bus, "mem", &[6]));
        let dup = status_of(&f, "J6 ", "duplicate-id");
        assert_eq!(dup.status, Status::Ok, "{f:#?}");
    }
}
