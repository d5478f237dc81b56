//! The recording: the CSV format's parser ([`Recording::parse`]), an MCAP recording's
//! samples as the same columns ([`Recording::from_mcap`]), and reading a file of either,
//! bounded in size ([`read_bytes_bounded`]).

use std::path::Path;

use anyhow::Context as _;

use crate::exit::usage;

/// The largest recording read, bytes (a 500 Hz recording of 14 signals for an hour is
/// about 40 MiB).
pub(crate) const MAX_CSV_BYTES: u64 = 64 << 20;

/// The longest line, bytes.
pub(crate) const MAX_LINE_BYTES: usize = 64 << 10;

/// The largest magnitude of a time or a value: beyond it the axes cannot be drawn with
/// meaningful ticks (and ±1e308 spans overflow to infinity).
pub(crate) const MAX_ABS_VALUE: f64 = 1e12;

/// A parsed recording.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Recording {
    /// Name of the time column.
    pub(crate) time_name: String,
    /// Times, one per row.
    pub(crate) time: Vec<f64>,
    /// Signals: name and one value per row (`None` = missing).
    pub(crate) signals: Vec<(String, Vec<Option<f64>>)>,
}

/// A CSV error at a line (from 1).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct CsvError {
    /// Line, from 1.
    pub(crate) line: usize,
    /// What is wrong.
    pub(crate) message: String,
}

impl Recording {
    /// Parses the CSV text.
    pub(crate) fn parse(text: &str) -> Result<Self, CsvError> {
        if let Some((i, l)) = text
            .lines()
            .enumerate()
            .find(|(_, l)| l.len() > MAX_LINE_BYTES)
        {
            return Err(CsvError {
                line: i + 1,
                message: format!(
                    "the line has {} bytes, more than the {MAX_LINE_BYTES} bytes (64 KiB) a \
                     line may have",
                    l.len()
                ),
            });
        }
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
        let Some((hline, header)) = lines.next() else {
            return Err(CsvError {
                line: text.lines().count().max(1),
                message: "no header line (expected e.g. `t_s,j1_deg`)".into(),
            });
        };
        let names: Vec<String> = header.split(',').map(|s| s.trim().to_owned()).collect();
        if names.len() < 2 {
            return Err(CsvError {
                line: hline,
                message: "the header needs a time column and at least one signal column".into(),
            });
        }
        if let Some((i, _)) = names.iter().enumerate().find(|(_, n)| n.is_empty()) {
            return Err(CsvError {
                line: hline,
                message: format!("column {} has an empty name", i + 1),
            });
        }
        let mut rec = Recording {
            time_name: names.first().cloned().unwrap_or_default(),
            time: Vec::new(),
            signals: names
                .iter()
                .skip(1)
                .map(|n| (n.clone(), Vec::new()))
                .collect(),
        };
        for (line, row) in lines {
            let cells: Vec<&str> = row.split(',').map(str::trim).collect();
            if cells.len() != names.len() {
                return Err(CsvError {
                    line,
                    message: format!(
                        "{} cells, the header has {} columns",
                        cells.len(),
                        names.len()
                    ),
                });
            }
            let mut values = cells
                .iter()
                .zip(&names)
                .enumerate()
                .map(|(i, (c, n))| cell(line, i, n, c));
            let t = values
                .next()
                .transpose()?
                .flatten()
                .ok_or_else(|| CsvError {
                    line,
                    message: format!("column 1 (`{}`): the time is missing", rec.time_name),
                })?;
            if rec.time.last().is_some_and(|&last| t < last) {
                return Err(CsvError {
                    line,
                    message: format!("time {t} is before the previous row's"),
                });
            }
            rec.time.push(t);
            for (slot, v) in rec.signals.iter_mut().zip(values) {
                slot.1.push(v?);
            }
        }
        if rec.time.is_empty() {
            return Err(CsvError {
                line: hline,
                message: "no data rows after the header".into(),
            });
        }
        Ok(rec)
    }
}

/// One cell: empty (a missing sample) or a finite number within [`MAX_ABS_VALUE`].
fn cell(line: usize, i: usize, name: &str, c: &str) -> Result<Option<f64>, CsvError> {
    if c.is_empty() {
        return Ok(None);
    }
    let v = c
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| CsvError {
            line,
            message: format!("column {} (`{name}`): `{c}` is not a number", i + 1),
        })?;
    if v.abs() > MAX_ABS_VALUE {
        return Err(CsvError {
            line,
            message: format!(
                "column {} (`{name}`): {c} is out of the plottable range -1e12..=1e12",
                i + 1
            ),
        });
    }
    Ok(Some(v))
}

impl Recording {
    /// The samples of an MCAP recording (`robobus monitor --record FILE.mcap`) as the
    /// CSV form's columns, held to the same limits as a CSV cell.
    pub(crate) fn from_mcap(bytes: &[u8]) -> Result<Self, String> {
        let cols = robobus::record::read_columns(bytes)?;
        let check = |what: &str, k: usize, v: f64| {
            if v.is_finite() && v.abs() <= MAX_ABS_VALUE {
                Ok(v)
            } else {
                Err(format!(
                    "sample {}: {what} {v} is out of the plottable range -1e12..=1e12",
                    k + 1
                ))
            }
        };
        for (k, pair) in cols.time.windows(2).enumerate() {
            if pair[1] < pair[0] {
                return Err(format!("sample {}: the time goes back", k + 2));
            }
        }
        for (k, &t) in cols.time.iter().enumerate() {
            check("t_s", k, t)?;
        }
        for (name, values) in &cols.signals {
            for (k, v) in values.iter().enumerate() {
                if let Some(v) = v {
                    check(name, k, *v)?;
                }
            }
        }
        Ok(Self {
            time_name: "t_s".into(),
            time: cols.time,
            signals: cols.signals,
        })
    }
}

/// Reads the recording's text (see [`read_bytes_bounded`]), refusing what is not UTF-8.
pub(super) fn read_bounded(path: &Path) -> anyhow::Result<String> {
    let bytes = read_bytes_bounded(path)?;
    String::from_utf8(bytes).map_err(|e| {
        usage(format!(
            "{}: not UTF-8 text (byte {} is invalid)",
            path.display(),
            e.utf8_error().valid_up_to()
        ))
    })
}

/// Reads the recording, refusing files over [`MAX_CSV_BYTES`] without reading further.
pub(super) fn read_bytes_bounded(path: &Path) -> anyhow::Result<Vec<u8>> {
    use std::io::Read as _;
    // A file that is not there is bad input: exit 2, nothing drawn.
    if !path.exists() {
        return Err(usage(format!(
            "{}: no such file (give a CSV or MCAP recording, e.g. from `robobus monitor \
             --record`)",
            path.display()
        )));
    }
    let file =
        std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut bytes = Vec::new();
    file.take(MAX_CSV_BYTES + 1)
        .read_to_end(&mut bytes)
        .with_context(|| format!("cannot read {}", path.display()))?;
    if bytes.len() as u64 > MAX_CSV_BYTES {
        return Err(usage(format!(
            "{}: larger than {MAX_CSV_BYTES} bytes (64 MiB), the limit for a recording",
            path.display()
        )));
    }
    Ok(bytes)
}
