//! One bounded quantity of the host's limits ([`Bound`]): the range a front end checks a
//! value against before anything is sent, and the message it refuses one with. The
//! catalogue's table of them is [`catalogue::bounds`](crate::catalogue::bounds).

use serde::Serialize;

use super::OpError;

/// One bounded quantity: its name as the CLI's option or argument, its unit and its range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, schemars::JsonSchema)]
pub struct Bound {
    /// The quantity, as the CLI's messages name it (`angle (degrees)`).
    pub what: &'static str,
    /// The unit (`deg`, `deg/s`, `RPM`, `mA`, `Hz`, `s`).
    pub unit: &'static str,
    /// Smallest value allowed.
    pub min: f64,
    /// Largest value allowed.
    pub max: f64,
}

impl Bound {
    /// Checks `value` against the bound: a finite number within `min..=max`; the error is
    /// the CLI's message (`angle (degrees) 400 is out of range -360..=360`).
    pub fn message(&self, value: f64) -> Option<String> {
        if !value.is_finite() {
            return Some(format!("`{value}` is not a finite number"));
        }
        (!(self.min..=self.max).contains(&value)).then(|| {
            format!(
                "{} {value} is out of range {}..={}",
                self.what, self.min, self.max
            )
        })
    }

    /// [`Bound::message`] as an [`OpError::Invalid`] naming `option`.
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    pub fn check(&self, option: &str, value: f64) -> Result<f64, OpError> {
        match self.message(value) {
            None => Ok(value),
            Some(m) => Err(OpError::invalid(
                option,
                value,
                format!("{m} (allowed: {}..={} {})", self.min, self.max, self.unit),
            )),
        }
    }
}
