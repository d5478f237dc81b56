//! The registry's machinery: `registry!` turns one row per operation into the
//! [`Request`](super::Request) enum, its conversions, the dispatch to each operation's
//! [`Operation`] methods, and the list of [`OpInfo`] the schemas and the operation table
//! are made from. The rows themselves are in `catalogue/mod.rs`.

use std::fmt::Write as _;

use robobus_wck::BaudRate;
use schemars::{JsonSchema, Schema, SchemaGenerator};

use super::effect::{Effect, Moved};
use super::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use super::plan::{Family, Plan};
use crate::ops::OpError;

/// An [`Operation`] behind a pointer: what the dispatcher calls, whichever operation a
/// request holds.
pub trait DynOperation {
    /// [`Operation::OP`].
    fn op(&self) -> &'static str;
    /// [`Operation::FAMILY`].
    fn family(&self) -> Family;
    /// [`Operation::bus`].
    fn bus(&self) -> Option<&str>;
    /// [`Operation::effect`].
    fn effect(&self) -> Effect;
    /// [`Operation::moved`].
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn moved(&self) -> Result<Option<Moved>, OpError>;
    /// [`Operation::confirmed`].
    fn confirmed(&self) -> bool;
    /// [`Operation::confirm`].
    fn confirm(&mut self);
    /// [`Operation::check`].
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn check(&self) -> Result<Confirm, OpError>;
    /// [`Operation::plan`].
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError>;
    /// [`Operation::run`], its report in JSON form.
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report, OpError>;
}

impl<O: Operation> DynOperation for O {
    fn op(&self) -> &'static str {
        O::OP
    }
    fn family(&self) -> Family {
        O::FAMILY
    }
    fn bus(&self) -> Option<&str> {
        Operation::bus(self)
    }
    fn effect(&self) -> Effect {
        Operation::effect(self)
    }
    fn moved(&self) -> Result<Option<Moved>, OpError> {
        Operation::moved(self)
    }
    fn confirmed(&self) -> bool {
        Operation::confirmed(self)
    }
    fn confirm(&mut self) {
        Operation::confirm(self);
    }
    fn check(&self) -> Result<Confirm, OpError> {
        Operation::check(self)
    }
    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError> {
        Operation::plan(self, baud)
    }
    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report, OpError> {
        Operation::run(self, cx).map(Report::erase)
    }
}

/// One registered operation: its name, family, table row and report schema.
#[derive(Clone, Copy)]
pub struct OpInfo {
    /// Its name (`"wck.status"`).
    pub op: &'static str,
    /// Its family.
    pub family: Family,
    /// Its row of the operation table.
    pub doc: OpDoc,
    report_schema: fn(&mut SchemaGenerator) -> Schema,
}

impl std::fmt::Debug for OpInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OpInfo")
            .field("op", &self.op)
            .field("family", &self.family)
            .finish_non_exhaustive()
    }
}

fn report_schema_of<O: Operation>(g: &mut SchemaGenerator) -> Schema {
    g.subschema_for::<Report<O::Row, O::Summary>>()
}

impl OpInfo {
    /// The entry of `O`.
    #[must_use]
    pub fn of<O: Operation>() -> Self {
        Self {
            op: O::OP,
            family: O::FAMILY,
            doc: O::DOC,
            report_schema: report_schema_of::<O>,
        }
    }

    /// The schema of its report (`$ref`s into `g`'s definitions).
    pub fn report_schema(&self, g: &mut SchemaGenerator) -> Schema {
        (self.report_schema)(g)
    }
}

/// The JSON Schema of every operation's report: one of them, each with its `op` and its
/// own rows and summary.
pub fn report_schema(ops: &[OpInfo]) -> serde_json::Value {
    let mut g = schemars::generate::SchemaSettings::draft2020_12().into_generator();
    let one_of: Vec<serde_json::Value> = ops
        .iter()
        .map(|info| {
            let report = info.report_schema(&mut g);
            serde_json::json!({
                "title": info.op,
                "allOf": [
                    report,
                    {"properties": {"op": {"const": info.op}}, "required": ["op"]},
                ],
            })
        })
        .collect();
    serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "Report",
        "description": "What a request did: `op`, `bus`, `results` (one row per device or register, \
                        typed per operation), `summary`, `failed` (the worst error kind) and `error`.",
        "oneOf": one_of,
        "$defs": g.take_definitions(true),
    })
}

/// The operation table in Markdown (what `catalogue/operations.md` holds).
pub fn operation_table(ops: &[OpInfo]) -> String {
    let mut out = String::from(
        "| op | arguments (units) | report `results` / `summary` | confirm |\n|---|---|---|---|\n",
    );
    for info in ops {
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} |",
            info.op, info.doc.args, info.doc.report, info.doc.confirm
        );
    }
    out
}

/// The JSON Schema of `T` as a root schema (for the request and the plan).
pub fn root_schema<T: JsonSchema>() -> serde_json::Value {
    serde_json::to_value(schemars::schema_for!(T)).unwrap_or_default()
}

/// Declares the [`Request`](super::Request) enum and its dispatch from one row per
/// operation: `"wck.status" => WckStatus(wck::Status),`. A row's name must be its
/// type's [`Operation::OP`] (checked when the crate compiles).
macro_rules! registry {
    ($( $(#[$meta:meta])* $op:literal => $variant:ident($ty:ty), )*) => {
        /// One request: an operation and its arguments (see the [module docs](self)).
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
        #[serde(tag = "op")]
        // A variant's docs would replace its request's own in the schema: none here.
        #[allow(missing_docs)]
        pub enum Request {
            $(
                $(#[$meta])*
                #[serde(rename = $op)]
                $variant($ty),
            )*
        }

        $(
            $(#[$meta])*
            impl From<$ty> for Request {
                fn from(r: $ty) -> Self {
                    Self::$variant(r)
                }
            }
            $(#[$meta])*
            const _: () = assert!(
                operation::same_name($op, <$ty as Operation>::OP),
                concat!("the registry's row ", $op, " holds another operation"),
            );
        )*

        impl Request {
            /// The operation it holds.
            pub fn operation(&self) -> &dyn registry::DynOperation {
                match self {
                    $( $(#[$meta])* Self::$variant(r) => r, )*
                }
            }

            /// The operation it holds, to change (confirm).
            pub fn operation_mut(&mut self) -> &mut dyn registry::DynOperation {
                match self {
                    $( $(#[$meta])* Self::$variant(r) => r, )*
                }
            }
        }

        /// Every registered operation, in the registry's order.
        #[must_use]
        pub fn operations() -> Vec<registry::OpInfo> {
            vec![ $( $(#[$meta])* registry::OpInfo::of::<$ty>(), )* ]
        }
    };
}
pub(crate) use registry;
