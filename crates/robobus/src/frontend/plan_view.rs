//! One plan view for every front end: what a request would send, as the studio's
//! preview, the bridge's `plan` queryable, Python's `Station.plan` and the CLI's
//! `--dry-run --json` show it.
//!
//! The [`Plan`]'s own fields (`op`, `family`, `notes`, `steps`, `confirm`: the class,
//! `confirm_text`, `truncated`), then `text` (the lines `--dry-run` prints), `effect`
//! (`read`, `configure`, `motion`) and `ask`: what a front end asks the user before the
//! request runs (its `confirm_text` while the request lacks `confirm: true`, `null`
//! otherwise).

use serde::Serialize;

use crate::catalogue::{self, Effect, Plan, Request};
use crate::ops::OpError;

/// A plan as every front end shows it (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlanView {
    /// The plan.
    #[serde(flatten)]
    pub plan: Plan,
    /// Its text form ([`Plan::to_text`]).
    pub text: String,
    /// What the request does to its devices.
    pub effect: Effect,
    /// What to ask the user before it runs; `None` when it runs as it is.
    pub ask: Option<String>,
}

impl PlanView {
    /// The view of `request`'s plan (nothing is opened).
    ///
    /// # Errors
    ///
    /// The request does not validate ([`catalogue::plan()`], [`catalogue::confirmation`]).
    pub fn of(request: &Request) -> Result<Self, OpError> {
        Self::at(request, robobus_wck::BaudRate::B115200)
    }

    /// [`PlanView::of`] with the wCK packets shown at `baud` (the rate of the port a run
    /// would use; [`catalogue::plan_at`]).
    ///
    /// # Errors
    ///
    /// The request does not validate.
    pub fn at(request: &Request, baud: robobus_wck::BaudRate) -> Result<Self, OpError> {
        let plan = catalogue::plan_at(request, baud)?;
        let ask = catalogue::confirmation(request)?;
        Ok(Self {
            text: plan.to_text().to_owned(),
            effect: request.effect(),
            ask,
            plan,
        })
    }

    /// As JSON.
    #[must_use]
    pub fn to_value(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_view_is_the_plan_its_text_effect_and_question() {
        let r: Request = serde_json::from_str(r#"{"op":"whj.save","joints":"4"}"#).unwrap();
        let v = PlanView::of(&r).unwrap().to_value();
        let plan = serde_json::to_value(catalogue::plan(&r).unwrap()).unwrap();
        for (k, val) in plan.as_object().unwrap() {
            assert_eq!(&v[k], val, "{k}");
        }
        assert_eq!(v["text"], catalogue::plan(&r).unwrap().to_text());
        assert_eq!(v["effect"], "configure");
        assert_eq!(v["ask"], v["confirm_text"]);
        assert!(v["ask"].as_str().is_some_and(|s| !s.is_empty()), "{v}");
        // Confirmed: nothing more to ask; the class stays.
        let v = PlanView::of(&r.confirmed()).unwrap().to_value();
        assert_eq!(v["ask"], serde_json::Value::Null);
        assert_eq!(v["confirm"], plan["confirm"]);
        let keys: Vec<&String> = v.as_object().unwrap().keys().collect();
        assert_eq!(keys.len(), plan.as_object().unwrap().len() + 3, "{keys:?}");
    }
}
