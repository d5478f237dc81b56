//! `whj.release-iap`: starts the application of joints held in their bootloader (the
//! first step of every connect), and reads who they are.

use robobus_wck::BaudRate;
use robobus_whj::{JointId, Request as Wire};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, bus_report, each, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::{self as hops, IdentityReport};
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `whj.release-iap`: start the application of joints in the bootloader (connect).
    ReleaseIap {
        /// Joint IDs, e.g. `1-7`.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
    }
);

/// A joint released from its bootloader: who it is.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct Released {
    /// Its identity, read after the release.
    #[serde(flatten)]
    pub identity: IdentityReport,
    /// Always `true`: it answered the release.
    pub released: bool,
}

impl ReleaseIap {
    fn ids(&self) -> R<Vec<JointId>> {
        self.joints.parse_sorted::<JointId>("<JOINTS>")
    }
}

impl Operation for ReleaseIap {
    const OP: &'static str = "whj.release-iap";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joints`",
        report: "identity (connect / IAP release)",
        confirm: "-",
    };
    type Row = DeviceResult<u8, Released>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> R<Confirm> {
        self.ids().map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        // The release is the connect's first step: no connect note.
        let steps = each(&self.ids()?, Wire::start_application);
        Ok(plan_of(Self::OP, steps, false, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let ids = self.ids()?;
        bus_report(cx, Self::OP, self.bus(), |b| {
            Ok(hops::release_iap(b, &ids)
                .into_iter()
                .map(|r| DeviceResult {
                    id: r.id,
                    outcome: r.outcome.map(|identity| Released {
                        identity,
                        released: true,
                    }),
                })
                .collect())
        })
    }
}
