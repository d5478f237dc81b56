//! `whj.write`: a register written in its unit and read back; its safety class decides
//! whether it is refused or needs confirming.

use robobus_wck::BaudRate;
use robobus_whj::registers::addr as reg;
use robobus_whj::units::CurrentScale;
use robobus_whj::{JointId, RegisterAddr, Request as Wire};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{Model, R, joint_list, one_joint, parse_end_board_register, parse_register};
use super::{parse_u32, plan_of, scale_for};
use crate::catalogue::args::Ids;
use crate::catalogue::bounds::{ConfirmClass, NON_VOLATILE_TEXT};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::{self as ops, EndBoardArg, RegisterReport, Slot};
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `whj.write`: a register in its unit, read back; the register's safety class decides
    /// (refused, or needs `confirm`).
    Write {
        /// Joint ID, 1..=30 (with `broadcast`: joints 1..=7, e.g. `1-7`).
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
        /// Register name (`cur_position`, `SYS_TEMP`) or address (`0x14`, `20`),
        /// 0x00..=0x91.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::register))]
        register: String,
        /// The value, in the register's unit (see `robobus whj registers`); with `raw`, in
        /// counts.
        #[cfg_attr(feature = "cli", arg(allow_hyphen_values = true, value_parser = crate::catalogue::whj::cli::finite))]
        value: f64,
        /// The value is in raw counts.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long))]
        raw: bool,
        /// Write the register of joints 1..=7 with one broadcast frame (0x0F), then read
        /// it back with a second one; a joint that does not answer is named.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long))]
        broadcast: bool,
        /// With `broadcast`: also write a register of the end board's own map,
        /// `REGISTER=VALUE` (e.g. `EB_IO1_MODE=1`, 0x07=3); needs confirming.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, value_name = "REGISTER=VALUE", requires = "broadcast", value_parser = crate::catalogue::whj::cli::end_board_write))]
        end_board: Option<String>,
        /// Model for the current scale of a plan.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        model: Option<Model>,
        /// Confirms a write of the `confirm` class.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        confirm: bool,
    }
);

/// A validated write: what a run needs.
struct Args {
    joints: Vec<JointId>,
    addr: RegisterAddr,
    end_board: Option<EndBoardArg>,
}

/// An end-board write, `REGISTER=VALUE`.
fn end_board_write(s: &str) -> Result<EndBoardArg, String> {
    let (reg, value) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}` is not REGISTER=VALUE (e.g. EB_IO1_MODE=1)"))?;
    let v = parse_u32(value.trim()).ok_or_else(|| format!("`{value}` is not a number"))?;
    let value = u16::try_from(v).map_err(|_| format!("value {v} is out of range 0..=65535"))?;
    Ok(EndBoardArg {
        addr: parse_end_board_register(reg)?,
        value: Some(value),
    })
}

impl Write {
    /// Validates it (`dry_run`: for a plan, whose mA-to-counts scale needs `model`): what
    /// a run needs, its frames and what it needs confirmed.
    fn prepare(&self, dry_run: bool) -> R<(Args, WhjSteps, Confirm)> {
        let ids = joint_list(&self.joints)?;
        let (addr, info) = parse_register(&self.register)
            .map_err(|e| OpError::invalid("<REGISTER>", &self.register, e))?;
        let name = info.map_or("reserved register", |i| i.name);
        if !self.value.is_finite() {
            return Err(OpError::invalid(
                "<VALUE>",
                self.value,
                "not a finite number",
            ));
        }
        // Motion targets and `never` registers are refused here, plan or run.
        if let Err(e @ OpError::Refused(_)) = ops::check_write(addr, true) {
            return Err(e);
        }
        let eb = self
            .end_board
            .as_deref()
            .map(|s| end_board_write(s).map_err(|e| OpError::invalid("--end-board", s, e)))
            .transpose()?;
        if eb.is_some() && !self.broadcast {
            return Err(OpError::invalid("end_board", "given", "needs broadcast"));
        }
        let scale = if ops::needs_current_scale(addr, self.raw) {
            scale_for(self.model, dry_run, &format!("write {name}"))?
        } else {
            CurrentScale::OneMilliamp
        };
        let (steps, confirm_text) = if self.broadcast {
            let b = ops::plan_broadcast_write(&ids, addr, self.value, self.raw, &|_| scale, eb)?;
            let text = b
                .frames
                .iter()
                .find_map(ops::confirm_text)
                .map(str::to_owned)
                .or_else(|| eb.map(|_| ops::END_BOARD_WRITE_TEXT.to_owned()));
            (WhjSteps::of_broadcast(&b), text)
        } else {
            let j = one_joint(&ids, "write <JOINT>")?;
            let req = ops::write_request(j, addr, self.value, self.raw, scale)?;
            let mut p = WhjSteps::default();
            p.push(req);
            let text = ops::confirm_text(&req).map(str::to_owned);
            if let Some(what) = &text {
                p.notes.push(format!("{name}: {what} (needs --yes)"));
            }
            (p, text)
        };
        let flash = steps.steps.iter().any(|(_, s)| {
            matches!(s, Wire::Write { addr, .. }
                if *addr == reg::SYS_SAVE_TO_FLASH || *addr == reg::SYS_ID)
        });
        let confirm = match confirm_text {
            Some(what) => Confirm::of(ConfirmClass::Register, format!("This write {what}.")),
            None if flash => Confirm::of(ConfirmClass::NonVolatile, NON_VOLATILE_TEXT),
            None => Confirm::NONE,
        };
        let args = Args {
            joints: ids,
            addr,
            end_board: eb,
        };
        Ok((args, steps, confirm))
    }
}

impl Operation for Write {
    const OP: &'static str = "whj.write";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joints`, `register`, `value` (register unit; counts with `raw`), `broadcast`, \
               `end_board` (`REG=VALUE`), `model`",
        report: "read-back",
        confirm: "register class / flash",
    };
    type Row = DeviceResult<Slot, RegisterReport>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Configure
    }

    fn confirmed(&self) -> bool {
        self.confirm
    }

    fn confirm(&mut self) {
        self.confirm = true;
    }

    fn check(&self) -> R<Confirm> {
        self.prepare(false).map(|(_, _, confirm)| confirm)
    }

    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        let (_, steps, confirm) = self.prepare(true)?;
        Ok(plan_of(Self::OP, steps, true, confirm))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let (a, _, _) = self.prepare(false)?;
        let port = cx.station.whj(self.bus())?;
        let bus = port.bus();
        let scale = self.model.map(Model::scale);
        let results = if self.broadcast {
            let (_, results) = ops::broadcast_write(
                bus,
                &a.joints,
                a.addr,
                self.value,
                self.raw,
                scale,
                a.end_board,
                self.confirm,
            )?;
            results
        } else {
            let mut rows = Vec::new();
            for &j in &a.joints {
                let read = ops::write(bus, j, a.addr, self.value, self.raw, scale, self.confirm)?;
                rows.extend(
                    read.into_iter()
                        .map(|r| DeviceResult::ok(Slot::Joint(j), r)),
                );
            }
            rows
        };
        Ok(Report::devices(Self::OP, port.name(), results))
    }
}
