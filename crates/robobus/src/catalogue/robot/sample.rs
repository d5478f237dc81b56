//! `robot.sample`: one reading of every joint of the station's robot file.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{ROBOT, no_robot};
use crate::catalogue::effect::Effect;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::{Family, Plan};
use crate::ops::{DeviceResult, OpError};
use crate::station::sampler::RobotJointSample;

/// `robot.sample`: one reading of every joint of the station's robot file, in the file's
/// order: its joint angle (deg, the file's `offset`, `direction` and wCK `centre`
/// applied), speed (deg/s; a wCK joint's from its previous reading on this station),
/// WHJ current and enable state, wCK load, error bits. Read-only. A joint that does not
/// answer is a row with its failure, never an older value.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Sample {}

/// What a `robot.sample` reads (its frames depend on the station's robot file).
const SAMPLE_NOTE: &str = "reads every joint of the station's robot file, read-only: a \
     status read per wCK servo (FF <0xA0|ID> 00 <checksum>), a status query (0x600+ID) and a \
     speed register read per WHJ joint; a real run first connects each WHJ joint once";

impl Operation for Sample {
    const OP: &'static str = "robot.sample";
    const FAMILY: Family = Family::Robot;
    const DOC: OpDoc = OpDoc {
        args: "-",
        report: "one row per joint of the station's robot file, `id` its name: \
                 `position_deg`, `speed_deg_s`, `current_ma` (WHJ), `effort_nm` (WHJ, from \
                 the current and the identified model), `load` (wCK), `enabled`, `error`",
        confirm: "-",
    };
    type Row = DeviceResult<String, RobotJointSample>;
    type Summary = ();

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> Result<Confirm, OpError> {
        Ok(Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        Ok(Plan::notes_only(
            Self::OP,
            Family::Robot,
            vec![SAMPLE_NOTE.into()],
        ))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let results = cx.station.sample_robot().ok_or_else(no_robot)??;
        Ok(Report::devices(Self::OP, ROBOT, results))
    }
}
