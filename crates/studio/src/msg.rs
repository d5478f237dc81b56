//! What the studio sends: every WebSocket message (`type`-tagged) and the HTTP API's JSON
//! bodies, as types (`docs/studio.md` lists them).

use robobus::catalogue::{Family, Report, Sample};
use robobus::frontend::guard::SafeEvent;
use robobus::station::jog::Jogged;
use serde::Serialize;

/// A message to a page over its WebSocket.
#[derive(Debug, Serialize)]
#[serde(tag = "type", rename_all = "kebab-case")]
pub(crate) enum ToPage<'a> {
    /// The first message: what the studio is.
    Hello {
        /// Started with `--read-only`.
        read_only: bool,
        /// On the built-in simulated robot.
        simulated: bool,
    },
    /// This page's view of control; the controller's carries its control secret.
    Control {
        /// This page controls.
        controller: bool,
        /// The controller is armed.
        armed: bool,
        /// Another page controls.
        held_by_other: bool,
        /// The control secret (only to the controlling page, over its own socket).
        secret: Option<String>,
    },
    /// A run's progress.
    Progress {
        /// The run.
        id: Option<u64>,
        /// What is being done.
        stage: &'a str,
        /// Steps done.
        done: u64,
        /// Steps in all, when known.
        total: Option<u64>,
        /// A short note.
        note: Option<&'a str>,
    },
    /// A run's report.
    Report {
        /// The run.
        id: u64,
        /// Its report.
        report: &'a Report,
    },
    /// A refusal or a failure, of a run or jog (`id`) or of the message itself.
    Error {
        /// The run or jog.
        id: Option<u64>,
        /// The error kind.
        kind: &'a str,
        /// The message.
        message: &'a str,
    },
    /// The latest sample of a stream, with how many were skipped since the previous one.
    Telemetry {
        /// The page's name of the stream.
        stream: &'a str,
        /// The sample.
        sample: &'a Sample,
        /// Samples not sent since the previous one.
        skipped: u64,
    },
    /// A commanded position target, to every page (its plots).
    Target {
        /// `wck` or `whj`.
        family: Family,
        /// The resolved bus.
        bus: &'a str,
        /// Servo or joint ID.
        device: u32,
        /// wCK steps, WHJ degrees.
        value: f64,
        /// When, ms since the Unix epoch.
        unix_ms: f64,
    },
    /// What a jog sent.
    Jogged {
        /// The jog's `id`, if it had one.
        id: Option<u64>,
        /// The step.
        #[serde(flatten)]
        jogged: &'a Jogged,
    },
    /// A safe stop the guard made, to every page.
    Safe(&'a SafeEvent),
}

impl ToPage<'_> {
    /// As the page receives it.
    pub(crate) fn text(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// An error body of the HTTP API.
#[derive(Debug, Serialize)]
pub(crate) struct ErrorBody<'a> {
    /// The error kind.
    pub(crate) kind: &'a str,
    /// The message.
    pub(crate) message: &'a str,
}

/// A bus by name (`/api/info`).
#[derive(Debug, Serialize)]
pub(crate) struct Named<'a> {
    /// The station's bus.
    pub(crate) name: &'a str,
}

/// A joint of the robot file (`/api/info`).
#[derive(Debug, Serialize)]
pub(crate) struct InfoJoint<'a> {
    /// Its name.
    pub(crate) name: &'a str,
    /// Its bus.
    pub(crate) bus: &'a str,
    /// `wck` or `whj`.
    pub(crate) family: &'a str,
    /// Its ID.
    pub(crate) id: u8,
}

/// `GET /api/info`.
#[derive(Debug, Serialize)]
pub(crate) struct Info<'a> {
    /// The studio's version.
    pub(crate) version: &'a str,
    /// Started with `--read-only`.
    pub(crate) read_only: bool,
    /// On the built-in simulated robot.
    pub(crate) simulated: bool,
    /// The wCK ports.
    pub(crate) wck: Vec<Named<'a>>,
    /// The WHJ buses.
    pub(crate) whj: Vec<Named<'a>>,
    /// The robot file's joints, if it has one.
    pub(crate) robot: Option<Vec<InfoJoint<'a>>>,
    /// How often an armed page beats, ms.
    pub(crate) heartbeat_ms: u64,
    /// The guard's heartbeat timeout, ms.
    pub(crate) heartbeat_timeout_ms: u128,
    /// Whether the buses are captured.
    pub(crate) capture: bool,
    /// The write rate limit.
    pub(crate) eeprom_writes_per_minute: usize,
}

/// A capture file (`GET /api/capture`).
#[derive(Debug, Serialize)]
pub(crate) struct CaptureFile<'a> {
    /// The bus.
    pub(crate) bus: &'a str,
    /// `hex` (wCK) or `candump` (WHJ).
    pub(crate) format: &'a str,
    /// Its size now.
    pub(crate) bytes: u64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn value(m: &ToPage<'_>) -> serde_json::Value {
        serde_json::from_str(&m.text()).unwrap()
    }

    #[test]
    fn messages_are_the_json_the_page_reads() {
        assert_eq!(
            value(&ToPage::Hello {
                read_only: true,
                simulated: false
            }),
            json!({"type": "hello", "read_only": true, "simulated": false})
        );
        assert_eq!(
            value(&ToPage::Control {
                controller: true,
                armed: false,
                held_by_other: false,
                secret: None
            }),
            json!({"type": "control", "controller": true, "armed": false,
                   "held_by_other": false, "secret": null})
        );
        assert_eq!(
            value(&ToPage::Error {
                id: Some(3),
                kind: "refused",
                message: "no"
            }),
            json!({"type": "error", "id": 3, "kind": "refused", "message": "no"})
        );
        assert_eq!(
            value(&ToPage::Progress {
                id: None,
                stage: "move",
                done: 1,
                total: Some(4),
                note: None
            }),
            json!({"type": "progress", "id": null, "stage": "move", "done": 1, "total": 4,
                   "note": null})
        );
        assert_eq!(
            value(&ToPage::Target {
                family: Family::Whj,
                bus: "sim-whj",
                device: 3,
                value: 10.0,
                unix_ms: 1.5
            }),
            json!({"type": "target", "family": "whj", "bus": "sim-whj", "device": 3,
                   "value": 10.0, "unix_ms": 1.5})
        );
        let j = Jogged {
            family: Family::Wck,
            bus: "sim-wck".into(),
            device: 2,
            target: 100.0,
            from: 90.0,
            sent: 98.0,
            limited: true,
            feedback: json!({"position": 98}),
        };
        let mut want = serde_json::to_value(&j).unwrap();
        want["type"] = json!("jogged");
        want["id"] = json!(7);
        assert_eq!(
            value(&ToPage::Jogged {
                id: Some(7),
                jogged: &j
            }),
            want
        );
        let e = SafeEvent {
            reason: "disarmed".into(),
            state: "hold".into(),
            devices: Vec::new(),
            stopped_runs: 0,
            failures: Vec::new(),
            took_ms: 1.0,
        };
        let mut want = serde_json::to_value(&e).unwrap();
        want["type"] = json!("safe");
        assert_eq!(value(&ToPage::Safe(&e)), want);
    }
}
