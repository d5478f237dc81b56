//! A servo's parameters: the EEPROM (kept across power cycles, optionally in a file) and
//! the runtime copies that the runtime set commands change (lost at power-off).

use std::fmt::Write as _;
use std::path::Path;

use robobus_wck::program::Program;
use robobus_wck::{
    Accel, BaudRate, Boundaries, DGain, ExtServoId, IGain, Overload, PGain, Position, Speed,
};

/// The EEPROM of one module. [`Eeprom::default`] holds the factory defaults of the
/// manual's A-5.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Eeprom {
    /// Module ID (0..=253; 4- and 6-byte commands reach 0..=30 only).
    pub id: ExtServoId,
    /// Baud rate.
    pub baud: BaudRate,
    /// P gain.
    pub p: PGain,
    /// D gain.
    pub d: DGain,
    /// I gain.
    pub i: IGain,
    /// Speed level (0 = no limit).
    pub speed: Speed,
    /// Acceleration range.
    pub accel: Accel,
    /// Over-load threshold.
    pub overload: Overload,
    /// Movement boundaries.
    pub bounds: Boundaries,
    /// Self-running motion program (empty = inactive).
    pub program: Program,
}

impl Default for Eeprom {
    fn default() -> Self {
        Self {
            id: ExtServoId::MIN,
            baud: BaudRate::DEFAULT,
            p: PGain::DEFAULT,
            d: DGain::DEFAULT,
            i: IGain::DEFAULT,
            speed: Speed::DEFAULT,
            accel: Accel::DEFAULT,
            overload: Overload::DEFAULT,
            bounds: Boundaries::DEFAULT,
            program: Program::EMPTY,
        }
    }
}

/// The values a module works with; at power-up a copy of the EEPROM's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Runtime {
    /// P gain in effect.
    pub p: PGain,
    /// D gain in effect.
    pub d: DGain,
    /// I gain in effect.
    pub i: IGain,
    /// Speed level in effect.
    pub speed: Speed,
    /// Acceleration range in effect.
    pub accel: Accel,
}

impl Runtime {
    /// The runtime values a module starts with.
    pub const fn from_eeprom(e: &Eeprom) -> Self {
        Self {
            p: e.p,
            d: e.d,
            i: e.i,
            speed: e.speed,
            accel: e.accel,
        }
    }
}

/// A saved EEPROM file that does not parse.
#[derive(Debug, thiserror::Error)]
pub enum EepromFileError {
    /// Reading or writing the file failed.
    #[error("EEPROM file {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The error.
        #[source]
        source: std::io::Error,
    },
    /// A line is not `key value` with a known key and a valid value.
    #[error("EEPROM file line {line}: {message}")]
    Syntax {
        /// Line number (from 1).
        line: usize,
        /// What is wrong.
        message: String,
    },
}

impl Eeprom {
    /// Writes the EEPROMs of several servos as text: one `servo <index>` line, then
    /// `key value` lines (`id`, `baud` (code), `p`, `d`, `i`, `speed`, `accel`, `overload`,
    /// `bounds <lower> <upper>`, `program <hex bytes>`).
    pub fn to_text(all: &[Self]) -> String {
        let mut s = String::from("# robobus-sim wCK EEPROM, one block per servo slot\n");
        for (n, e) in all.iter().enumerate() {
            let _ = writeln!(s, "servo {n}");
            let _ = writeln!(s, "id {}", e.id.get());
            let _ = writeln!(s, "baud {}", e.baud.code());
            let _ = writeln!(s, "p {}", e.p.get());
            let _ = writeln!(s, "d {}", e.d.get());
            let _ = writeln!(s, "i {}", e.i.get());
            let _ = writeln!(s, "speed {}", e.speed.get());
            let _ = writeln!(s, "accel {}", e.accel.get());
            let _ = writeln!(s, "overload {}", e.overload.get());
            let _ = writeln!(
                s,
                "bounds {} {}",
                e.bounds.lower().get(),
                e.bounds.upper().get()
            );
            let _ = write!(s, "program");
            for (c, d) in e.program.pairs() {
                let _ = write!(s, " {c:02X} {d:02X}");
            }
            s.push('\n');
        }
        s
    }

    /// Reads what [`Eeprom::to_text`] wrote. Keys missing from a block keep the defaults.
    pub fn from_text(text: &str) -> Result<Vec<Self>, EepromFileError> {
        let mut out: Vec<Self> = Vec::new();
        for (n, raw) in text.lines().enumerate() {
            let line = n + 1;
            let err = |message: String| EepromFileError::Syntax { line, message };
            let body = raw.split('#').next().unwrap_or("").trim();
            if body.is_empty() {
                continue;
            }
            let mut words = body.split_whitespace();
            let key = words.next().unwrap_or("");
            let values: Vec<&str> = words.collect();
            let num = |i: usize, radix: u32| -> Result<u8, EepromFileError> {
                let v = values
                    .get(i)
                    .ok_or_else(|| err(format!("`{key}` needs a value")))?;
                u8::from_str_radix(v, radix)
                    .map_err(|_| err(format!("`{v}` is not a byte value for `{key}`")))
            };
            if key == "servo" {
                out.push(Self::default());
                continue;
            }
            let Some(e) = out.last_mut() else {
                return Err(err("a `servo <n>` line must come first".into()));
            };
            let bad = |x: &dyn std::fmt::Display| err(format!("{key}: {x}"));
            match key {
                "id" => e.id = ExtServoId::new(num(0, 10)?).map_err(|x| bad(&x))?,
                "baud" => e.baud = BaudRate::from_code(num(0, 10)?).map_err(|x| bad(&x))?,
                "p" => e.p = PGain::new(num(0, 10)?).map_err(|x| bad(&x))?,
                "d" => e.d = DGain::new(num(0, 10)?).map_err(|x| bad(&x))?,
                "i" => e.i = IGain::new(num(0, 10)?).map_err(|x| bad(&x))?,
                "speed" => e.speed = Speed::new(num(0, 10)?).map_err(|x| bad(&x))?,
                "accel" => e.accel = Accel::new(num(0, 10)?).map_err(|x| bad(&x))?,
                "overload" => e.overload = Overload::new(num(0, 10)?).map_err(|x| bad(&x))?,
                "bounds" => {
                    let lower = Position::new(num(0, 10)?).map_err(|x| bad(&x))?;
                    let upper = Position::new(num(1, 10)?).map_err(|x| bad(&x))?;
                    e.bounds = Boundaries::new(lower, upper).map_err(|x| bad(&x))?;
                }
                "program" => {
                    let mut bytes = Vec::with_capacity(values.len());
                    for i in 0..values.len() {
                        bytes.push(num(i, 16)?);
                    }
                    e.program = Program::from_bytes(&bytes).map_err(|x| bad(&x))?;
                }
                other => return Err(err(format!("unknown key `{other}`"))),
            }
        }
        Ok(out)
    }

    /// Saves several EEPROMs to a file.
    pub fn save(all: &[Self], path: &Path) -> Result<(), EepromFileError> {
        std::fs::write(path, Self::to_text(all)).map_err(|source| EepromFileError::Io {
            path: path.display().to_string(),
            source,
        })
    }

    /// The largest EEPROM file [`Eeprom::load`] reads: 1 MiB (31 servos with full
    /// programs take about 20 KiB).
    pub const MAX_FILE_BYTES: u64 = 1 << 20;

    /// Loads several EEPROMs from a file of at most [`Eeprom::MAX_FILE_BYTES`]: a larger
    /// (or endless) file is refused after that many bytes, never read whole.
    pub fn load(path: &Path) -> Result<Vec<Self>, EepromFileError> {
        use std::io::Read as _;
        let io = |source| EepromFileError::Io {
            path: path.display().to_string(),
            source,
        };
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .map_err(io)?
            .take(Self::MAX_FILE_BYTES + 1)
            .read_to_end(&mut bytes)
            .map_err(io)?;
        if bytes.len() as u64 > Self::MAX_FILE_BYTES {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                "larger than the limit of 1 MiB",
            )));
        }
        let text = String::from_utf8(bytes).map_err(|e| {
            io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
            ))
        })?;
        Self::from_text(&text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_endless_or_oversized_file_is_refused_with_the_limit() {
        let e = Eeprom::load(Path::new("/dev/zero")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "EEPROM file /dev/zero: larger than the limit of 1 MiB"
        );
    }

    #[test]
    fn defaults_are_a5() {
        let e = Eeprom::default();
        assert_eq!(e.baud.code(), 7);
        assert_eq!((e.p.get(), e.d.get(), e.i.get()), (20, 30, 0));
        assert_eq!(e.id.get(), 0);
        assert_eq!((e.speed.get(), e.accel.get()), (0, 60));
        assert_eq!(e.overload.get(), 33);
        assert_eq!((e.bounds.lower().get(), e.bounds.upper().get()), (1, 254));
        assert!(e.program.is_empty());
    }

    #[test]
    fn text_round_trips() {
        let a = Eeprom {
            id: ExtServoId::new(200).unwrap(),
            baud: BaudRate::B9600,
            p: PGain::new(77).unwrap(),
            program: Program::from_bytes(&[0x10, 0x52, 0x31, 0x0A, 0x10, 0xAC, 0x31, 0x0A])
                .unwrap(),
            ..Eeprom::default()
        };
        let all = vec![a, Eeprom::default()];
        let text = Eeprom::to_text(&all);
        assert_eq!(Eeprom::from_text(&text).unwrap(), all);
    }

    #[test]
    fn bad_text_names_the_line() {
        let err = Eeprom::from_text("servo 0\nbaud 5\n").unwrap_err();
        assert!(err.to_string().contains("line 2"), "{err}");
        let err = Eeprom::from_text("id 3\n").unwrap_err();
        assert!(err.to_string().contains("line 1"), "{err}");
    }
}
