//! `whj.sample`: one monitor sample of joints (what a telemetry stream takes).

use robobus_wck::BaudRate;
use robobus_whj::{JointId, Request as Wire};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::{self as hops, JointSample};
use crate::ops::{DeviceResult, OpError};

request!(
    /// `whj.sample`: one monitor sample (status and servo feedback, or one broadcast
    /// status frame).
    Sample {
        /// Joint IDs.
        joints: Ids,
        /// One broadcast status frame.
        #[serde(default)]
        broadcast: bool,
    }
);

impl Sample {
    /// The joints and the frames of one sample.
    fn steps(&self) -> R<(Vec<JointId>, WhjSteps)> {
        let ids = self.joints.parse_sorted::<JointId>("<JOINTS>")?;
        let mut p = WhjSteps::default();
        if self.broadcast {
            let mask = hops::reply_mask(&ids)?;
            p.push(Wire::BroadcastStatus(
                robobus_whj::broadcast::BroadcastStatus::new(mask),
            ));
        } else {
            for &j in &ids {
                p.push(Wire::StatusQuery { joint: j });
            }
            p.notes
                .push("status query and servo feedback of each joint".into());
        }
        Ok((ids, p))
    }
}

impl Operation for Sample {
    const OP: &'static str = "whj.sample";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joints`, `broadcast`",
        report: "position, speed, current, enabled, error",
        confirm: "-",
    };
    type Row = DeviceResult<u8, JointSample>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> R<Confirm> {
        self.steps().map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        Ok(plan_of(Self::OP, self.steps()?.1, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let (ids, _) = self.steps()?;
        let port = cx.station.whj(self.bus())?;
        let bus = port.bus();
        // Joints this bus has not connected yet are connected first (together; a silent
        // one shows in its row), once per station: a telemetry stream does not wait for a
        // silent joint's connect at every sample.
        let _ = bus.joints(&port.untried(&ids));
        // The fastest way the bus allows (pipelined, broadcast, the cyclic loop's feedback).
        let (results, _by) = crate::station::sampler::sample_whj(bus, &ids, self.broadcast)?;
        Ok(Report::devices(Self::OP, port.name(), results))
    }
}
