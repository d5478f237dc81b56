//! The one plan type of both families: what a request sends, in order, with the time each
//! packet or frame is due. Its text form is what the CLI's `--dry-run` prints.

use std::fmt::Write as _;

use robobus_wck::BaudRate;
use robobus_whj::{CanFrame, Request as WhjWire};
use schemars::JsonSchema;
use serde::Serialize;

use crate::ops::wck::WckPlan;

/// One packet (wCK) or frame (WHJ) of a plan.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct PlanStep {
    /// When it is due, ms after the start; `null` = right after the previous exchange.
    pub t_ms: Option<f64>,
    /// wCK: the rate it goes at, bit/s (`null` for WHJ).
    pub baud: Option<u32>,
    /// WHJ: the CAN ID (`null` for wCK).
    pub can_id: Option<u32>,
    /// What it is: the manual's command name (wCK) or the request (WHJ).
    pub what: String,
    /// The bytes (wCK: the packet; WHJ: the frame's data).
    pub bytes: Vec<u8>,
    /// The line `--dry-run` prints: `FF 03 7F 7C` (wCK) or `001##1020A01` (cansend).
    pub line: String,
}

pub use crate::ops::Family;

/// The plan of a request.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Plan {
    /// The operation (`wck.status`).
    pub op: String,
    /// The family.
    pub family: Family,
    /// Notes: assumptions (a dry run's start position), pacing, what needs confirmation.
    pub notes: Vec<String>,
    /// The packets / frames.
    pub steps: Vec<PlanStep>,
    /// Whether the request needs `confirm: true`, and why.
    pub confirm: super::bounds::ConfirmClass,
    /// What a front end asks before it sets `confirm: true` (the CLI's prompt), when the
    /// request needs it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub confirm_text: Option<String>,
    /// `true` when the steps are a shortened view of a streamed plan (a keyframe motion's
    /// moves are generated as they are sent: the first ones are listed).
    pub truncated: bool,
    /// The text form (see [`Plan::to_text`]).
    #[serde(skip)]
    text: String,
}

/// The most steps a plan lists (a motion streams its moves; a scan of all rates stays far
/// below).
pub const MAX_PLAN_STEPS: usize = 100_000;

/// The note a WHJ plan opens with: the connect a real run sends each joint first (its
/// IAP release, repeated until the joint answers, then its identity reads:
/// [`crate::whj::Joint::connect_requests`]). `None` for no joints.
pub fn connect_note(joints: &[robobus_whj::JointId]) -> Option<String> {
    if joints.is_empty() {
        return None;
    }
    let each: Vec<String> = joints
        .iter()
        .map(|&j| {
            let frames: Vec<String> = crate::whj::Joint::connect_requests(j)
                .iter()
                .map(|r| frame_line(&r.to_frame()))
                .collect();
            format!("joint {}: {}", j.get(), frames.join(" "))
        })
        .collect();
    Some(format!(
        "before these frames a real run connects each joint: its IAP release (repeated \
         until the joint answers), then its identity reads; {}",
        each.join("; ")
    ))
}

/// A frame in `cansend` syntax: `001##1020A01` (FD) or `001#0102` (classic).
pub fn frame_line(f: &CanFrame) -> String {
    f.to_string()
}

impl Plan {
    pub(crate) fn wck(op: &str, plan: &WckPlan, baud: BaudRate) -> Self {
        let steps = plan
            .steps
            .iter()
            .map(|s| {
                let p = s.packet(baud);
                PlanStep {
                    t_ms: s.at_ms.map(|ms| ms as f64),
                    baud: Some(p.baud),
                    can_id: None,
                    what: format!("{} {}", p.command, p.target),
                    bytes: p.bytes,
                    line: p.hex,
                }
            })
            .collect();
        Self {
            op: op.to_owned(),
            family: Family::Wck,
            notes: plan.notes.clone(),
            steps,
            confirm: super::bounds::ConfirmClass::None,
            confirm_text: None,
            truncated: false,
            text: plan.to_text(),
        }
    }

    pub(crate) fn whj(op: &str, plan: &WhjSteps) -> Self {
        let steps = plan
            .steps
            .iter()
            .map(|(at_us, r)| {
                let f = r.to_frame();
                PlanStep {
                    t_ms: at_us.map(|us| us as f64 / 1000.0),
                    baud: None,
                    can_id: Some(f.raw_id()),
                    what: format!("{r:?}"),
                    bytes: f.data().to_vec(),
                    line: frame_line(&f),
                }
            })
            .collect();
        let mut p = Self {
            op: op.to_owned(),
            family: Family::Whj,
            notes: plan.notes.clone(),
            steps,
            confirm: super::bounds::ConfirmClass::None,
            confirm_text: None,
            truncated: false,
            text: String::new(),
        };
        let mut text = String::new();
        for n in &p.notes {
            let _ = writeln!(text, "# {n}");
        }
        for st in &p.steps {
            let _ = writeln!(text, "{}", st.line);
        }
        p.text = text;
        p
    }

    /// A plan of notes only: what a request sends depends on the station (a robot file's
    /// buses and joints), so a plan without one can say what it reads, not the frames.
    pub(crate) fn notes_only(op: &str, family: Family, notes: Vec<String>) -> Self {
        let mut text = String::new();
        for n in &notes {
            let _ = writeln!(text, "# {n}");
        }
        Self {
            op: op.to_owned(),
            family,
            notes,
            steps: Vec::new(),
            confirm: super::bounds::ConfirmClass::None,
            confirm_text: None,
            truncated: false,
            text,
        }
    }

    /// The text form `--dry-run` prints: `# note` lines, then one line per step (wCK: a
    /// rate line where a scan of every rate changes rates).
    pub fn to_text(&self) -> &str {
        &self.text
    }
}

/// A WHJ plan while it is built: requests with their due times (µs) and notes.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct WhjSteps {
    pub(crate) notes: Vec<String>,
    pub(crate) steps: Vec<(Option<u64>, WhjWire)>,
}

impl WhjSteps {
    pub(crate) fn push(&mut self, r: WhjWire) {
        self.steps.push((None, r));
    }
    pub(crate) fn push_at(&mut self, at_us: u64, r: WhjWire) {
        self.steps.push((Some(at_us), r));
    }
    /// The library's plan of a move or wave: assumptions and notes, reads, timed frames.
    pub(crate) fn of(plan: &crate::ops::whj::Plan) -> Self {
        let mut p = Self::default();
        p.notes.extend(plan.assumed.iter().cloned());
        p.notes.extend(plan.notes.iter().cloned());
        for r in &plan.reads {
            p.push(*r);
        }
        for f in &plan.frames {
            #[allow(clippy::cast_possible_truncation)] // at most hours, in µs
            p.push_at(f.at.as_micros() as u64, f.request);
        }
        p
    }
    pub(crate) fn of_broadcast(b: &crate::ops::whj::BroadcastPlan) -> Self {
        let mut p = Self::default();
        for f in &b.frames {
            p.push(*f);
        }
        p.notes.clone_from(&b.notes);
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use robobus_whj::JointId;

    #[test]
    fn frame_lines_use_cansend_syntax() {
        let j1 = JointId::new(1).unwrap();
        assert_eq!(
            frame_line(&WhjWire::enable(j1, true).to_frame()),
            "001##1020A01"
        );
        assert_eq!(
            frame_line(&WhjWire::StatusQuery { joint: j1 }.to_frame()),
            "601##1"
        );
    }
}
