//! `wck.program.check`: a motion program parsed, and the packet that would upload it;
//! nothing is sent.

use robobus_wck::program::Program;
use robobus_wck::{BaudRate, Command, ServoId};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{NoRow, R, plan_of, program, sid};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;
use crate::ops::wck::WckPlan;

request!(cli
    /// `wck.program.check`: parse a program and show its upload packet (nothing sent).
    ProgramCheck {
        /// Servo ID for the printed upload packet, 0..=30.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, default_value = "0", value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
        /// The program text.
        #[cfg_attr(feature = "cli", arg(skip))]
        program: String,
    }
);

/// What `wck.program.check` found: the program's instructions and its upload packet.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct ProgramCheckSummary {
    /// Always `true`: the program parsed (a program that does not is a bad-input error).
    pub ok: bool,
    /// The instructions, in order.
    pub instructions: Vec<Instruction>,
    /// The packet that uploads it (A-1 (24)).
    pub upload_packet: UploadPacket,
}

/// One instruction of a motion program.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct Instruction {
    /// Its text form.
    pub text: String,
    /// Its command byte.
    pub command: u8,
    /// Its data byte.
    pub data: u8,
}

/// The upload packet of a program.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct UploadPacket {
    /// The servo it is for.
    pub id: u8,
    /// Its bytes in hex.
    pub hex: String,
    /// Its bytes.
    pub bytes: Vec<u8>,
}

impl ProgramCheck {
    /// The servo and the program, validated.
    fn parsed(&self) -> R<(ServoId, Program)> {
        Ok((sid(self.id)?, program(&self.program)?))
    }
}

impl Operation for ProgramCheck {
    const OP: &'static str = "wck.program.check";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`program`, `id`=0",
        report: "no rows; `summary`: `ok`, `instructions` (`text`, `command`, `data`), \
                 `upload_packet` (`id`, `hex`, `bytes`); nothing is sent",
        confirm: "-",
    };
    type Row = NoRow;
    type Summary = ProgramCheckSummary;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.parsed().map(|_| Confirm::NONE)
    }

    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError> {
        let (id, program) = self.parsed()?;
        let plan = WckPlan::one(Command::MotionWrite { id, program });
        Ok(plan_of(Self::OP, &plan, baud, ConfirmClass::None))
    }

    /// Sends nothing: no port is needed (the report's `bus` is the one named, if any).
    fn run(&self, _cx: &mut RunCx<'_, '_>) -> Result<Report<NoRow, Self::Summary>, OpError> {
        let (id, program) = self.parsed()?;
        let packet = Command::MotionWrite { id, program }.encode();
        let instructions = program
            .instructions()
            .iter()
            .map(|i| {
                let (command, data) = i.to_pair();
                Instruction {
                    text: i.to_string(),
                    command,
                    data,
                }
            })
            .collect();
        let summary = ProgramCheckSummary {
            ok: true,
            instructions,
            upload_packet: UploadPacket {
                id: id.get(),
                hex: packet.to_string(),
                bytes: packet.as_bytes().to_vec(),
            },
        };
        Ok(Report::new(Self::OP, self.bus().unwrap_or("")).summary(summary))
    }
}
