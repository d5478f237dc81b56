//! A test operation, `test.echo`: what adding an operation takes. This file and one
//! `#[cfg(test)]` row of the registry (`catalogue/mod.rs`) are all of it; the tests below
//! find it in the parser, the dispatcher, the confirmation rule, the schemas and the
//! operation table.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::bounds::ConfirmClass;
use super::effect::Effect;
use super::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use super::plan::{Family, Plan};
use crate::ops::OpError;

/// `test.echo`: says `text` back, once per `times`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Echo {
    /// What to say back (at most 16 characters).
    pub text: String,
    /// How many rows (1..=3).
    #[serde(default = "one")]
    pub times: u8,
    /// Confirms an echo of `"EEPROM"` (a pretend non-volatile write).
    #[serde(default)]
    pub confirm: bool,
}

const fn one() -> u8 {
    1
}

/// One row of its report.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct EchoRow {
    /// The row's number, from 1.
    pub id: u8,
    /// The text said back.
    pub text: String,
}

/// Its summary.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct EchoSummary {
    /// How many rows.
    pub rows: u8,
}

impl Operation for Echo {
    const OP: &'static str = "test.echo";
    const FAMILY: Family = Family::Host;
    const DOC: OpDoc = OpDoc {
        args: "`text` (1..=16 characters), `times`=1 (1..=3)",
        report: "one row per time: `id`, `text`; `summary`: `rows`",
        confirm: "`text` \"EEPROM\"",
    };
    type Row = EchoRow;
    type Summary = EchoSummary;

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn confirmed(&self) -> bool {
        self.confirm
    }

    fn confirm(&mut self) {
        self.confirm = true;
    }

    fn check(&self) -> Result<Confirm, OpError> {
        if self.text.is_empty() || self.text.chars().count() > 16 {
            return Err(OpError::invalid(
                "text",
                &self.text,
                "allowed: 1..=16 characters",
            ));
        }
        if !(1..=3).contains(&self.times) {
            return Err(OpError::invalid("times", self.times, "allowed: 1..=3"));
        }
        Ok(if self.text == "EEPROM" {
            Confirm::of(ConfirmClass::NonVolatile, "This pretends to write EEPROM.")
        } else {
            Confirm::NONE
        })
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let confirm = self.check()?;
        let mut plan = Plan::notes_only(Self::OP, Family::Host, vec!["sends nothing".into()]);
        plan.confirm = confirm.class;
        plan.confirm_text = confirm.text;
        Ok(plan)
    }

    fn run(&self, _cx: &mut RunCx<'_, '_>) -> Result<Report<EchoRow, EchoSummary>, OpError> {
        let rows = (1..=self.times)
            .map(|id| EchoRow {
                id,
                text: self.text.clone(),
            })
            .collect();
        Ok(Report::with_rows(Self::OP, "host", rows).summary(EchoSummary { rows: self.times }))
    }
}

#[cfg(test)]
mod tests {

    use super::*;
    use crate::catalogue::{self, Request};
    use crate::ops::{Control, StopToken};
    use crate::station::Station;

    fn run(json: &str) -> Result<Report, OpError> {
        let station = Station::new();
        let stop = StopToken::new();
        catalogue::run(&station, &Request::parse(json)?, &mut Control::new(&stop))
    }

    #[test]
    fn a_registered_operation_parses_plans_runs_and_is_confirmed_like_any_other() {
        let r = Request::parse(r#"{"op": "test.echo", "text": "hi", "times": 2}"#).unwrap();
        assert_eq!(
            (r.op(), r.family(), r.effect()),
            ("test.echo", Family::Host, Effect::Read)
        );
        assert_eq!(
            catalogue::plan(&r).unwrap().notes,
            vec!["sends nothing".to_owned()]
        );
        let report = run(r#"{"op": "test.echo", "text": "hi", "times": 2}"#).unwrap();
        assert_eq!(
            serde_json::to_value(&report).unwrap(),
            serde_json::json!({
                "op": "test.echo", "bus": "host",
                "results": [{"id": 1, "text": "hi"}, {"id": 2, "text": "hi"}],
                "summary": {"rows": 2},
            })
        );
        // Out of range: bad input naming the value and the range.
        let e = run(r#"{"op": "test.echo", "text": "hi", "times": 4}"#).unwrap_err();
        assert_eq!(e.kind(), crate::ErrorKind::BadInput);
        assert!(e.to_string().contains("1..=3"), "{e}");
        // Its confirmation class holds through the one dispatcher.
        let eeprom = r#"{"op": "test.echo", "text": "EEPROM"}"#;
        assert_eq!(run(eeprom).unwrap_err().kind(), crate::ErrorKind::Refused);
        let asked = catalogue::confirmation(&Request::parse(eeprom).unwrap()).unwrap();
        assert_eq!(asked.as_deref(), Some("This pretends to write EEPROM."));
        let confirmed = Request::parse(eeprom).unwrap().confirmed();
        assert_eq!(catalogue::confirmation(&confirmed).unwrap(), None);
    }

    #[test]
    fn a_registered_operation_is_in_the_schemas_and_the_table() {
        let requests = catalogue::request_schema().to_string();
        assert!(requests.contains("\"test.echo\""));
        let reports = catalogue::report_schema();
        let echo = reports["oneOf"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["title"] == "test.echo")
            .unwrap();
        // Its own rows: the schema names the row type's fields.
        assert!(reports.to_string().contains("EchoRow"), "{echo}");
        assert!(catalogue::operation_table().contains(
            "| `test.echo` | `text` (1..=16 characters), `times`=1 (1..=3) | one row per time"
        ));
    }
}
