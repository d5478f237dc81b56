//! The robot requests (`robot.*`): a station's robot file read as one robot, its joints by
//! name in joint units, across every bus the file names.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// `robot.sample`: one reading of every joint of the station's robot file, in the file's
/// order: its joint angle (deg, the file's `offset`, `direction` and wCK `centre`
/// applied), speed (deg/s; a wCK joint's from its previous reading on this station),
/// WHJ current and enable state, wCK load, error bits. Read-only. A joint that does not
/// answer is a row with its failure, never an older value.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Sample {}
