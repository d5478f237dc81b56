//! The grouping of a recording's signals into panels ([`panels`]): each signal's family
//! and unit from its name, the targets beside their signals, the axis titles.

use std::collections::{HashMap, HashSet};

/// The units a signal's name may end in: suffix (matched ignoring case), the quantity and
/// the unit as the axis title writes them. `robobus monitor` writes `_deg`, `_rpm` (WHJ),
/// `_deg_per_s` (wCK), `_mA` and `_load`.
const UNITS: [(&str, &str, &str); 9] = [
    ("_deg_per_s", "speed", "deg/s"),
    ("_deg_s", "speed", "deg/s"),
    ("_rad_per_s", "speed", "rad/s"),
    ("_rad_s", "speed", "rad/s"),
    ("_rpm", "speed", "rpm"),
    ("_deg", "angle", "deg"),
    ("_rad", "angle", "rad"),
    ("_ma", "current", "mA"),
    ("_load", "load", ""),
];

/// The units a time column's name may end in, and how the axis title writes them.
const TIME_UNITS: [(&str, &str); 6] = [
    ("_s", "s"),
    ("_ms", "ms"),
    ("_us", "µs"),
    ("_ns", "ns"),
    ("_min", "min"),
    ("_h", "h"),
];

/// The kind of device a signal belongs to, from its name's prefix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Family {
    /// `wck…`, `s<N>`, `servo<N>`: a RoboBuilder wCK servo.
    Wck,
    /// `whj…`, `j<N>`, `joint<N>`: a RealMan WHJ joint.
    Whj,
    /// Anything else (a robot file's joint names, plain names).
    Other,
}

/// What a signal's name says: its family and the index of its unit in [`UNITS`].
fn classify(name: &str) -> (Family, Option<usize>) {
    let lower = name.to_ascii_lowercase();
    let unit = UNITS
        .iter()
        .position(|(suffix, ..)| lower.len() > suffix.len() && lower.ends_with(suffix));
    let stem = unit
        .and_then(|u| UNITS.get(u))
        .and_then(|(suffix, ..)| lower.get(..lower.len() - suffix.len()))
        .unwrap_or(&lower);
    let numbered = |prefix: &str| {
        stem.strip_prefix(prefix)
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
    };
    let family = if stem.starts_with("wck") || numbered("s") || numbered("servo") {
        Family::Wck
    } else if stem.starts_with("whj") || numbered("j") || numbered("joint") {
        Family::Whj
    } else {
        Family::Other
    };
    (family, unit)
}

/// The y-axis title of a panel of `family` and unit (an index in [`UNITS`]).
fn axis_title(family: Family, unit: Option<usize>) -> String {
    let what = match family {
        Family::Wck => "wCK servo ",
        Family::Whj => "WHJ joint ",
        Family::Other => "",
    };
    match unit.and_then(|u| UNITS.get(u)) {
        Some((_, quantity, "")) => format!("{what}{quantity}"),
        Some((_, quantity, unit)) => format!("{what}{quantity} ({unit})"),
        None => format!("{what}value"),
    }
}

/// The x-axis title for the time column `name`: `t_s` → `time (s)`, `elapsed_ms` →
/// `elapsed (ms)`; a name without a known unit stays as it is (but `t` → `time`).
pub(crate) fn time_title(name: &str) -> String {
    let lower = name.to_ascii_lowercase();
    let what = |stem: &str| {
        if stem.eq_ignore_ascii_case("t") || stem.eq_ignore_ascii_case("time") {
            "time".to_owned()
        } else {
            stem.to_owned()
        }
    };
    for (suffix, unit) in TIME_UNITS {
        if lower.len() > suffix.len()
            && lower.ends_with(suffix)
            && let Some(stem) = name.get(..name.len() - suffix.len())
        {
            return format!("{} ({unit})", what(stem));
        }
    }
    what(name)
}

/// The signal a target column `name` is the target of: `_target` taken out before the
/// unit or at the end (`j1_target_deg` and `j1_deg_target` → `j1_deg`). `None`: not a
/// target's name.
pub(super) fn target_of(name: &str) -> Option<String> {
    let lower = name.to_ascii_lowercase();
    let at = lower.rfind("_target")?;
    let rest = name.get(at + "_target".len()..)?;
    (at > 0 && (rest.is_empty() || rest.starts_with('_')))
        .then(|| format!("{}{rest}", name.get(..at).unwrap_or_default()))
}

/// One line of a panel: a signal and its target, as indexes in
/// [`Recording::signals`](super::Recording::signals).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Series {
    /// The signal (drawn solid).
    pub(crate) signal: usize,
    /// Its target (drawn dashed in the same colour), if the recording has one.
    pub(crate) target: Option<usize>,
}

/// One panel of the figure: the signals of one family and unit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Panel {
    /// The y-axis title, e.g. `WHJ joint angle (deg)`.
    pub(crate) title: String,
    /// Its lines, in column order.
    pub(crate) series: Vec<Series>,
}

/// Groups the signal columns `names` into panels, in the order their first signal comes:
/// one panel per family and unit ([`classify`]). A target column goes with the signal it
/// is the target of ([`target_of`]; the first column of that name); a target without
/// its signal is drawn as a signal of its own, in the panel its signal would be in.
pub(crate) fn panels<S: AsRef<str>>(names: &[S]) -> Vec<Panel> {
    let names: Vec<&str> = names.iter().map(AsRef::as_ref).collect();
    let mut first: HashMap<&str, usize> = HashMap::new();
    for (i, name) in names.iter().enumerate() {
        first.entry(name).or_insert(i);
    }
    // The signal each target column names, if the recording has it.
    let partner: Vec<Option<usize>> = names
        .iter()
        .map(|name| target_of(name).and_then(|a| first.get(a.as_str()).copied()))
        .collect();
    // Each signal's target: the first column naming it (a target has none of its own).
    let mut target: Vec<Option<usize>> = vec![None; names.len()];
    for (j, p) in partner.iter().enumerate() {
        if let Some(a) = *p
            && partner.get(a) == Some(&None)
            && let Some(slot) = target.get_mut(a)
            && slot.is_none()
        {
            *slot = Some(j);
        }
    }
    let attached: HashSet<usize> = target.iter().flatten().copied().collect();
    let mut keys: Vec<(Family, Option<usize>)> = Vec::new();
    let mut panels: Vec<Panel> = Vec::new();
    for (i, name) in names.iter().enumerate() {
        if attached.contains(&i) {
            continue;
        }
        let key = classify(&target_of(name).unwrap_or_else(|| (*name).to_owned()));
        let series = Series {
            signal: i,
            target: target.get(i).copied().flatten(),
        };
        if let Some(panel) = keys
            .iter()
            .position(|k| *k == key)
            .and_then(|p| panels.get_mut(p))
        {
            panel.series.push(series);
        } else {
            keys.push(key);
            panels.push(Panel {
                title: axis_title(key.0, key.1),
                series: vec![series],
            });
        }
    }
    panels
}
