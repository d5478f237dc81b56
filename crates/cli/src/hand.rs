//! `--hand` of the simulators: a device's shaft turned back and forth by hand, as someone
//! calibrating or teaching a robot does.

use crate::exit::usage;

/// `--hand`: a device's shaft turned back and forth by hand.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Hand {
    /// The device.
    pub(crate) id: u8,
    from: f64,
    to: f64,
    period: f64,
}

impl Hand {
    /// `ID:FROM:TO:PERIOD`, ID one of the bus's, the angles within ±`max_deg`, the period
    /// 0.05..=600 s.
    pub(crate) fn parse(text: &str, ids: &[u8], max_deg: f64) -> anyhow::Result<Self> {
        let bad = |why: &str| {
            usage(format!(
                "--hand {text}: {why} (ID:FROM:TO:PERIOD, e.g. 0:-40:50:1)"
            ))
        };
        let parts: Vec<&str> = text.split(':').collect();
        let [id, from, to, period] = parts.as_slice() else {
            return Err(bad("four fields"));
        };
        let id: u8 = id
            .trim()
            .parse()
            .map_err(|_| bad("the ID is not a number"))?;
        if !ids.contains(&id) {
            return Err(bad("no device with this ID on the bus"));
        }
        let angle = |a: &str| {
            a.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && (-max_deg..=max_deg).contains(v))
                .ok_or_else(|| bad(&format!("an angle out of range -{max_deg}..={max_deg}°")))
        };
        let period = period
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|p| p.is_finite() && (0.05..=600.0).contains(p))
            .ok_or_else(|| bad("a period out of range 0.05..=600 s"))?;
        Ok(Self {
            id,
            from: angle(from)?,
            to: angle(to)?,
            period,
        })
    }

    /// The angle at `t` seconds: from FROM to TO in the first half period, back in the
    /// second.
    pub(crate) fn angle(&self, t: f64) -> f64 {
        let phase = (t / self.period).fract();
        let x = if phase < 0.5 {
            phase * 2.0
        } else {
            2.0 - phase * 2.0
        };
        self.from + (self.to - self.from) * x
    }
}
