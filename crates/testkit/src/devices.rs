//! Which devices a client suite runs against: the simulators by default, or real devices
//! named by environment variables.
//!
//! | Variable | Meaning |
//! |---|---|
//! | `ROBOBUS_TEST_WCK_PORT` | the serial port of a wCK bus (`/dev/ttyUSB0`) |
//! | `ROBOBUS_TEST_WCK_BAUD` | its rate, bit/s (default 115200) |
//! | `ROBOBUS_TEST_WCK_IDS` | every servo on that bus (`0-3,5`; required with the port) |
//! | `ROBOBUS_TEST_WHJ_BUS` | a WHJ bus (`can0`, `udp`, `udp:GROUP:PORT`) |
//! | `ROBOBUS_TEST_WHJ_JOINTS` | every joint on that bus (`1-6`; required with the bus) |
//! | `ROBOBUS_TEST_MOTION` | `1`: the suite may move the devices (small moves near where they are); anything else or unset: it only reads |
//!
//! With neither a port nor a bus set, the suite runs on the simulators and moves them.
//! List *every* device on a bus: a suite picks the lowest ID not listed as one that must
//! stay silent.

use std::ffi::OsStr;

/// A wCK bus of real servos.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WckDevices {
    /// The serial port.
    pub port: String,
    /// Its rate, bit/s.
    pub baud: u32,
    /// Every servo on it.
    pub ids: Vec<u8>,
}

/// A WHJ bus of real joints.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WhjDevices {
    /// The bus address.
    pub bus: String,
    /// Every joint on it.
    pub joints: Vec<u8>,
}

/// Real devices a suite runs against.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Hardware {
    /// A wCK bus, if one is named.
    pub wck: Option<WckDevices>,
    /// A WHJ bus, if one is named.
    pub whj: Option<WhjDevices>,
    /// Whether the suite may move them.
    pub motion: bool,
}

/// The real devices the environment names, or `None` (run on the simulators).
///
/// # Panics
/// With the variable, its value and what it takes, when a variable is malformed or a
/// port or bus comes without its ID list.
#[must_use]
pub fn hardware() -> Option<Hardware> {
    hardware_from(|k| std::env::var_os(k)).unwrap_or_else(|e| panic!("{e}"))
}

/// [`hardware`] on any environment (`get` reads a variable).
///
/// # Errors
/// The variable, its value and what it takes.
pub fn hardware_from(
    get: impl Fn(&str) -> Option<std::ffi::OsString>,
) -> Result<Option<Hardware>, String> {
    let text = |k: &str| -> Result<Option<String>, String> {
        get(k)
            .map(|v| {
                v.into_string()
                    .map_err(|v| format!("{k}={}: not UTF-8", OsStr::new(&v).display()))
            })
            .transpose()
            .map(|v| v.filter(|s| !s.trim().is_empty()))
    };
    let wck = match text("ROBOBUS_TEST_WCK_PORT")? {
        None => None,
        Some(port) => {
            let baud = match text("ROBOBUS_TEST_WCK_BAUD")? {
                None => 115_200,
                Some(b) => b
                    .trim()
                    .parse::<u32>()
                    .ok()
                    .filter(|b| (4800..=921_600).contains(b))
                    .ok_or_else(|| {
                        format!("ROBOBUS_TEST_WCK_BAUD={b}: a rate in 4800..=921600 bit/s")
                    })?,
            };
            let ids = ids("ROBOBUS_TEST_WCK_IDS", text("ROBOBUS_TEST_WCK_IDS")?, 0, 30)?;
            Some(WckDevices { port, baud, ids })
        }
    };
    let whj = match text("ROBOBUS_TEST_WHJ_BUS")? {
        None => None,
        Some(bus) => {
            let joints = ids(
                "ROBOBUS_TEST_WHJ_JOINTS",
                text("ROBOBUS_TEST_WHJ_JOINTS")?,
                1,
                30,
            )?;
            Some(WhjDevices { bus, joints })
        }
    };
    if wck.is_none() && whj.is_none() {
        return Ok(None);
    }
    let motion = text("ROBOBUS_TEST_MOTION")?.is_some_and(|m| m.trim() == "1");
    Ok(Some(Hardware { wck, whj, motion }))
}

/// An ID list (`0-3,5`) of IDs in `lo..=hi`, from variable `key`.
fn ids(key: &str, value: Option<String>, lo: u8, hi: u8) -> Result<Vec<u8>, String> {
    let value = value.ok_or_else(|| {
        format!("{key} is not set: list every device on the bus (IDs {lo}..={hi}, as 0-3,5)")
    })?;
    let bad = || format!("{key}={value}: IDs in {lo}..={hi}, as 0-3,5");
    let one = |s: &str| {
        s.trim()
            .parse::<u8>()
            .ok()
            .filter(|i| (lo..=hi).contains(i))
    };
    let mut out = Vec::new();
    for part in value.split(',') {
        match part.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (one(a).ok_or_else(bad)?, one(b).ok_or_else(bad)?);
                if a > b {
                    return Err(bad());
                }
                out.extend(a..=b);
            }
            None => out.push(one(part).ok_or_else(bad)?),
        }
    }
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

/// The lowest ID in `lo..=hi` that `listed` does not hold (a device that must be silent).
#[must_use]
pub fn absent(listed: &[u8], lo: u8, hi: u8) -> Option<u8> {
    (lo..=hi).find(|i| !listed.contains(i))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn env(vars: &[(&str, &str)]) -> Result<Option<Hardware>, String> {
        let vars: Vec<(String, String)> = vars
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect();
        hardware_from(move |k| {
            vars.iter()
                .find(|(n, _)| n == k)
                .map(|(_, v)| v.clone().into())
        })
    }

    #[test]
    fn nothing_named_runs_on_the_simulators() {
        assert_eq!(env(&[]).unwrap(), None);
        assert_eq!(env(&[("ROBOBUS_TEST_MOTION", "1")]).unwrap(), None);
        assert_eq!(env(&[("ROBOBUS_TEST_WCK_PORT", " ")]).unwrap(), None);
    }

    #[test]
    fn named_devices_are_parsed_and_only_read_unless_motion_is_1() {
        let h = env(&[
            ("ROBOBUS_TEST_WCK_PORT", "/dev/ttyUSB0"),
            ("ROBOBUS_TEST_WCK_IDS", "3,0-2,2"),
            ("ROBOBUS_TEST_WHJ_BUS", "can0"),
            ("ROBOBUS_TEST_WHJ_JOINTS", "1-3"),
        ])
        .unwrap()
        .unwrap();
        assert_eq!(
            h.wck,
            Some(WckDevices {
                port: "/dev/ttyUSB0".into(),
                baud: 115_200,
                ids: vec![0, 1, 2, 3],
            })
        );
        assert_eq!(h.whj.unwrap().joints, [1, 2, 3]);
        assert!(!h.motion);
        let h = env(&[
            ("ROBOBUS_TEST_WHJ_BUS", "udp"),
            ("ROBOBUS_TEST_WHJ_JOINTS", "2"),
            ("ROBOBUS_TEST_MOTION", "1"),
        ])
        .unwrap()
        .unwrap();
        assert!(h.motion && h.wck.is_none());
    }

    #[test]
    fn malformed_variables_name_themselves_and_the_range() {
        for (vars, want) in [
            (
                &[("ROBOBUS_TEST_WCK_PORT", "/dev/ttyUSB0")][..],
                "ROBOBUS_TEST_WCK_IDS is not set",
            ),
            (
                &[
                    ("ROBOBUS_TEST_WCK_PORT", "/dev/ttyUSB0"),
                    ("ROBOBUS_TEST_WCK_IDS", "0-31"),
                ][..],
                "ROBOBUS_TEST_WCK_IDS=0-31: IDs in 0..=30",
            ),
            (
                &[
                    ("ROBOBUS_TEST_WCK_PORT", "/dev/ttyUSB0"),
                    ("ROBOBUS_TEST_WCK_IDS", "0"),
                    ("ROBOBUS_TEST_WCK_BAUD", "9600x"),
                ][..],
                "ROBOBUS_TEST_WCK_BAUD=9600x: a rate in 4800..=921600",
            ),
            (
                &[
                    ("ROBOBUS_TEST_WHJ_BUS", "can0"),
                    ("ROBOBUS_TEST_WHJ_JOINTS", "0"),
                ][..],
                "ROBOBUS_TEST_WHJ_JOINTS=0: IDs in 1..=30",
            ),
            (
                &[
                    ("ROBOBUS_TEST_WHJ_BUS", "can0"),
                    ("ROBOBUS_TEST_WHJ_JOINTS", "3-1"),
                ][..],
                "ROBOBUS_TEST_WHJ_JOINTS=3-1",
            ),
        ] {
            let e = env(vars).unwrap_err();
            assert!(e.contains(want), "{e} (wanted {want})");
        }
    }

    #[test]
    fn the_absent_id_is_the_lowest_not_listed() {
        assert_eq!(absent(&[0, 1, 2], 0, 30), Some(3));
        assert_eq!(absent(&[2, 3], 1, 30), Some(1));
        assert_eq!(absent(&(1..=30).collect::<Vec<_>>(), 1, 30), None);
    }
}
