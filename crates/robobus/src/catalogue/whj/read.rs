//! `whj.read`: registers by name or address, from one joint or with one broadcast frame
//! (joints 1..=7 and an end-board register).

use robobus_wck::BaudRate;
use robobus_whj::registers::Half;
use robobus_whj::{JointId, RegisterAddr, Request as Wire};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, joint_list, one_joint, parse_end_board_register, parse_register, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::{self as ops, RegisterReport, Slot};
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `whj.read`: registers by name or address.
    Read {
        /// Joint ID, 1..=30 (with `broadcast`: joints 1..=7, e.g. `1-7`).
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
        /// Register name (`cur_position`, `SYS_TEMP`) or address (`0x14`, `20`),
        /// 0x00..=0x91.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::register))]
        register: String,
        /// Number of registers, 1..=31 (default: 2 for a 32-bit pair, else 1).
        #[serde(default)]
        count: Option<u8>,
        /// Read the register of joints 1..=7 with one broadcast frame (0x0F) instead of
        /// one request each; a joint that does not answer is named.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long))]
        broadcast: bool,
        /// With `broadcast`: also read this register of the end board's own map (name or
        /// address, e.g. `EB_SW_VERSION` or 0x03).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, value_name = "REGISTER", requires = "broadcast", value_parser = crate::catalogue::whj::cli::end_board_register))]
        end_board: Option<String>,
    }
);

/// A validated `whj.read`: the joints, the register, the end-board register, the frames.
struct Parsed {
    joints: Vec<JointId>,
    addr: RegisterAddr,
    end_board: Option<u8>,
    steps: WhjSteps,
}

impl Read {
    fn parsed(&self) -> R<Parsed> {
        let joints = joint_list(&self.joints)?;
        let (addr, info) = parse_register(&self.register)
            .map_err(|e| OpError::invalid("<REGISTER>", &self.register, e))?;
        let end_board = self
            .end_board
            .as_deref()
            .map(|s| parse_end_board_register(s).map_err(|e| OpError::invalid("--end-board", s, e)))
            .transpose()?;
        if end_board.is_some() && !self.broadcast {
            return Err(OpError::invalid("end_board", "given", "needs broadcast"));
        }
        let steps = if self.broadcast {
            let plan = ops::plan_broadcast_read(&joints, addr, self.count, end_board)?;
            WhjSteps::of_broadcast(&plan)
        } else {
            let j = one_joint(&joints, "read <JOINT>")?;
            let count = self.count.unwrap_or(match info.map(|i| i.half) {
                Some(Half::Low) => 2,
                _ => 1,
            });
            let mut steps = WhjSteps::default();
            steps.push(
                Wire::read(j, addr, count)
                    .map_err(|e| OpError::invalid("[COUNT]", count, e.to_string()))?,
            );
            steps
        };
        Ok(Parsed {
            joints,
            addr,
            end_board,
            steps,
        })
    }
}

impl Operation for Read {
    const OP: &'static str = "whj.read";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joints`, `register` (name or address), `count`, `broadcast`, `end_board`",
        report: "one row per register: `addr`, `register`, `raw`, `value` (null without a \
                 fixed scale), `unit`; broadcast: one row per joint (and `end-board`), a \
                 silent one `no-device`",
        confirm: "-",
    };
    type Row = DeviceResult<Slot, RegisterReport>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.parsed().map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        Ok(plan_of(Self::OP, self.parsed()?.steps, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let p = self.parsed()?;
        let port = cx.station.whj(self.bus())?;
        let (name, bus) = (port.name(), port.bus());
        if self.broadcast {
            let (_, results) =
                ops::broadcast_read(bus, &p.joints, p.addr, self.count, p.end_board)?;
            return Ok(Report::devices(Self::OP, name, results));
        }
        let mut rows = Vec::new();
        for &j in &p.joints {
            let read = ops::read_registers(bus, j, p.addr, self.count)?;
            rows.extend(
                read.into_iter()
                    .map(|r| DeviceResult::ok(Slot::Joint(j), r)),
            );
        }
        Ok(Report::with_rows(Self::OP, name, rows))
    }
}
