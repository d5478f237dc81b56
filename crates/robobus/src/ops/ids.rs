//! Lists of device IDs as users write them: `3`, `0-5,7`, `0x10-0x12` (one parser for
//! every front end and both families).

use core::fmt;
use core::str::FromStr;

use robobus_wck::{ExtServoId, ServoId};
use robobus_whj::JointId;
use serde::Serialize;

/// An ID type that can appear in an [`IdList`].
pub trait ListId: Copy + PartialEq + fmt::Debug {
    /// What one ID is called in messages (`"servo ID"`).
    const WHAT: &'static str;
    /// The lowest raw ID.
    const MIN: u32;
    /// The highest raw ID.
    const MAX: u32;
    /// The ID with this raw value (in `MIN..=MAX`).
    fn from_raw(raw: u32) -> Option<Self>;
    /// The raw value.
    fn raw(self) -> u32;
}

impl ListId for ServoId {
    const WHAT: &'static str = "servo ID";
    const MIN: u32 = 0;
    const MAX: u32 = ServoId::MAX.get() as u32;
    fn from_raw(raw: u32) -> Option<Self> {
        u8::try_from(raw).ok().and_then(|b| Self::new(b).ok())
    }
    fn raw(self) -> u32 {
        self.get().into()
    }
}

impl ListId for ExtServoId {
    const WHAT: &'static str = "10-bit servo ID";
    const MIN: u32 = 0;
    const MAX: u32 = ExtServoId::MAX.get() as u32;
    fn from_raw(raw: u32) -> Option<Self> {
        u8::try_from(raw).ok().and_then(|b| Self::new(b).ok())
    }
    fn raw(self) -> u32 {
        self.get().into()
    }
}

impl ListId for JointId {
    const WHAT: &'static str = "joint ID";
    const MIN: u32 = JointId::MIN.get() as u32;
    const MAX: u32 = JointId::MAX.get() as u32;
    fn from_raw(raw: u32) -> Option<Self> {
        u8::try_from(raw).ok().and_then(|b| Self::new(b).ok())
    }
    fn raw(self) -> u32 {
        self.get().into()
    }
}

/// A non-empty list of IDs in the order written, without repeats.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(transparent)]
pub struct IdList<T>(Vec<T>);

impl<T> IdList<T> {
    /// The IDs, in the order written.
    pub fn as_slice(&self) -> &[T] {
        &self.0
    }

    /// The IDs.
    pub fn into_vec(self) -> Vec<T> {
        self.0
    }
}

impl<T: ListId> IdList<T> {
    /// A list of these IDs (order kept, repeats dropped); `None` when empty.
    pub fn new(ids: impl IntoIterator<Item = T>) -> Option<Self> {
        let mut v: Vec<T> = Vec::new();
        for id in ids {
            if !v.contains(&id) {
                v.push(id);
            }
        }
        (!v.is_empty()).then_some(Self(v))
    }

    /// The same IDs in ascending order.
    #[must_use]
    pub fn sorted(mut self) -> Self {
        self.0.sort_by_key(|id| id.raw());
        self
    }
}

/// `0-2,5`: servo IDs as ranges (what [`IdList`] parses back).
pub fn ids_text(ids: &[ServoId]) -> String {
    let mut raw: Vec<u8> = ids.iter().map(|i| i.get()).collect();
    raw.sort_unstable();
    raw.dedup();
    let mut runs: Vec<(u8, u8)> = Vec::new();
    for id in raw {
        match runs.last_mut() {
            Some((_, hi)) if hi.checked_add(1) == Some(id) => *hi = id,
            _ => runs.push((id, id)),
        }
    }
    runs.iter()
        .map(|&(lo, hi)| {
            if lo == hi {
                lo.to_string()
            } else {
                format!("{lo}-{hi}")
            }
        })
        .collect::<Vec<_>>()
        .join(",")
}

/// IDs given as numbers (a front end's list, in its order): at least one, each in the
/// type's range, none twice; `option` and `plural` name them in the refusal
/// (`ids 31: servo ID 31 is out of range (allowed: 0..=30)`).
#[allow(clippy::result_large_err)] // OpError, as every operation returns
pub fn distinct_ids<T: ListId>(
    option: &str,
    plural: &str,
    raw: &[u8],
) -> Result<Vec<T>, super::OpError> {
    use super::OpError;
    if raw.is_empty() {
        return Err(OpError::invalid(option, "[]", format!("no {plural} given")));
    }
    let mut out: Vec<T> = Vec::with_capacity(raw.len());
    for &r in raw {
        let id = T::from_raw(u32::from(r)).ok_or_else(|| {
            OpError::invalid(
                option,
                r,
                format!(
                    "{} {r} is out of range (allowed: {}..={})",
                    T::WHAT,
                    T::MIN,
                    T::MAX
                ),
            )
        })?;
        if out.contains(&id) {
            return Err(OpError::invalid(option, r, "given twice"));
        }
        out.push(id);
    }
    Ok(out)
}

/// Longest ID list text accepted (a list of every ID fits many times over).
const MAX_SPEC_LEN: usize = 1024;

/// A number: decimal or `0x` hex.
fn number(s: &str) -> Option<u32> {
    let t = s.trim();
    match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16).ok(),
        None => t.parse().ok(),
    }
}

impl<T: ListId> FromStr for IdList<T> {
    type Err = String;

    fn from_str(spec: &str) -> Result<Self, String> {
        let range = format!("{}..={}", T::MIN, T::MAX);
        if spec.len() > MAX_SPEC_LEN {
            return Err(format!(
                "the {} list is {} characters long (at most {MAX_SPEC_LEN})",
                T::WHAT,
                spec.len()
            ));
        }
        let one = |s: &str| -> Result<u32, String> {
            let v = number(s).ok_or_else(|| format!("`{}` is not a whole number", s.trim()))?;
            if T::from_raw(v).is_none() {
                return Err(format!("{} {v} is out of range {range}", T::WHAT));
            }
            Ok(v)
        };
        let mut ids = Vec::new();
        let parts: Vec<&str> = spec.split(',').map(str::trim).collect();
        if !spec.trim().is_empty()
            && let Some(k) = parts.iter().position(|p| p.is_empty())
        {
            return Err(format!(
                "`{spec}`: item {} is empty (separate IDs by single commas: `1,2,5-7`)",
                k + 1
            ));
        }
        for part in parts.into_iter().filter(|p| !p.is_empty()) {
            let (lo, hi) = if let Some((a, b)) = part.split_once('-') {
                (one(a)?, one(b)?)
            } else {
                let v = one(part)?;
                (v, v)
            };
            if lo > hi {
                return Err(format!(
                    "range {lo}-{hi} runs backwards (write the lower ID first)"
                ));
            }
            ids.extend((lo..=hi).filter_map(T::from_raw));
        }
        Self::new(ids).ok_or_else(|| {
            format!(
                "`{spec}` names no {}s (examples: `{min}`, `{min}-{}`; allowed {range})",
                T::WHAT,
                T::MIN + 3,
                min = T::MIN.max(1)
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_parse_in_order_without_repeats() {
        let l: IdList<ServoId> = "5,0-2,1,0x1E".parse().unwrap();
        let raw: Vec<u8> = l.as_slice().iter().map(|i| i.get()).collect();
        assert_eq!(raw, [5, 0, 1, 2, 30]);
        let j: IdList<JointId> = "3,1-2".parse().unwrap();
        let raw: Vec<u8> = j.sorted().as_slice().iter().map(|i| i.get()).collect();
        assert_eq!(raw, [1, 2, 3]);
    }

    #[test]
    fn bad_lists_name_the_value_and_the_range() {
        let e = "0-31".parse::<IdList<ServoId>>().unwrap_err();
        assert_eq!(e, "servo ID 31 is out of range 0..=30");
        let e = "0".parse::<IdList<JointId>>().unwrap_err();
        assert_eq!(e, "joint ID 0 is out of range 1..=30");
        let e = "4-2".parse::<IdList<JointId>>().unwrap_err();
        assert_eq!(e, "range 4-2 runs backwards (write the lower ID first)");
        let e = "  ".parse::<IdList<ServoId>>().unwrap_err();
        assert!(
            e.contains("names no servo IDs") && e.contains("0..=30"),
            "{e}"
        );
        // Empty items are refused, never skipped.
        let e = "1,,2".parse::<IdList<ServoId>>().unwrap_err();
        assert_eq!(
            e,
            "`1,,2`: item 2 is empty (separate IDs by single commas: `1,2,5-7`)"
        );
        assert!(
            "1,".parse::<IdList<JointId>>()
                .unwrap_err()
                .contains("item 2 is empty")
        );
        assert!(
            " , "
                .parse::<IdList<JointId>>()
                .unwrap_err()
                .contains("item 1 is empty")
        );
        let e = "x".parse::<IdList<ServoId>>().unwrap_err();
        assert_eq!(e, "`x` is not a whole number");
        let long = "1,".repeat(2000);
        assert!(
            long.parse::<IdList<ServoId>>()
                .unwrap_err()
                .contains("at most 1024")
        );
    }
}
