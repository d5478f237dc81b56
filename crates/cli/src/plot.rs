//! `robobus plot`: plot a recording (CSV) to a PNG or SVG file.
//!
//! # Recording format
//!
//! [`FORMAT_HELP`]: plain CSV, comma-separated, no quoting; the first non-comment line is
//! the header, the first column is time, every other column is one signal. An empty cell
//! is a missing sample. `robobus monitor` writes this format.
//!
//! ```text
//! t_s,j1_deg,j1_target_deg,j1_mA
//! 0.000,0.0,0.0,12
//! 0.002,0.1,0.2,15
//! ```
//!
//! # The figure
//!
//! Stacked panels share the time axis: one per family and unit of the signals
//! ([`panels`]), read from the column names: the unit from the suffix (`_deg`, `_rpm`,
//! `_mA`, ...), the family from the prefix (`wck3` / `s3`: wCK servos, `whj1` / `j1`: WHJ
//! joints). Each panel's y axis is titled with both (`WHJ joint angle (deg)`), the time
//! axis with the time column's unit (`t_s`: `time (s)`). A column named like another with
//! `_target` before its unit (`j1_target_deg` beside `j1_deg`, or `j1_deg_target`) is that
//! signal's target: drawn dashed, in the signal's colour, in its panel.
//!
//! # Text
//!
//! All text is drawn with `DejaVu Sans`, embedded in the binary (crate `dejavu`), so plots
//! look the same on a machine without fonts; SVG names the font family (falling back to
//! the viewer's sans-serif) and lets the viewer draw the text. On a bitmap, plotters
//! 0.3.7's own text drawing puts every glyph's outline at the pen position, dropping its
//! left side bearing, so a glyph with a wide bearing (`1`, `h`) sits too far left of the
//! next one and labels read `wh j1 _deg`. So this module lays text out itself ([`Pen`]):
//! each glyph's outline is rasterized by plotters but placed at the pen plus its side
//! bearing, from the font's own tables ([`FontMetrics`]).

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{Context as _, anyhow};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::Global;
use crate::exit::usage;

/// `--help` text describing the CSV format.
pub(crate) const FORMAT_HELP: &str = "\
Recording format (CSV, what `robobus monitor` writes):
  * comma-separated, no quoting; lines starting with `#` and blank lines are ignored
  * the first line is the header: the time column first (its name and unit title the
    x axis: `t_s` is \"time (s)\", also _ms, _us), then one column per signal (`j1_deg`,
    `s3_load`, ...)
  * every further line: a time and one number per signal; an empty cell is a missing
    sample; times must not decrease
  * limits: numbers within ±1e12, lines up to 64 KiB, files up to 64 MiB
The plot has one panel per family and unit, sharing the time axis:
  * unit: the name's suffix: _deg, _rad, _deg_s or _deg_per_s, _rad_s, _rpm, _mA, _load
    (a name without one is a \"value\")
  * family: the name's prefix: wck3, s3, servo3 are wCK servos; whj1, j1, joint1 WHJ joints
  * a column named like a signal with _target before its unit (`j1_target_deg`) or at
    the end (`j1_deg_target`) is that signal's target, drawn dashed in its colour
Example:
  t_s,j1_deg,j1_target_deg,j1_mA
  0.000,0.0,0.0,12
  0.002,0.1,0.2,15";

/// Options of `robobus plot`.
#[derive(Debug, clap::Args)]
#[command(after_help = FORMAT_HELP)]
pub(crate) struct Args {
    /// The recording (CSV, see below).
    file: PathBuf,
    /// Output file; the format follows the extension: .png or .svg.
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
    /// Only these signals (column names, comma-separated) and their targets; default all.
    #[arg(long, value_delimiter = ',')]
    signals: Vec<String>,
    /// Title (default: the file name).
    #[arg(long)]
    title: Option<String>,
    /// Image width in pixels (200..=8000).
    #[arg(long, default_value_t = 1200, value_parser = clap::value_parser!(u32).range(200..=8000))]
    width: u32,
    /// Image height in pixels (150..=8000; default: 240 per panel and 120, at least 600).
    #[arg(long, value_parser = clap::value_parser!(u32).range(150..=8000))]
    height: Option<u32>,
}

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
fn target_of(name: &str) -> Option<String> {
    let lower = name.to_ascii_lowercase();
    let at = lower.rfind("_target")?;
    let rest = name.get(at + "_target".len()..)?;
    (at > 0 && (rest.is_empty() || rest.starts_with('_')))
        .then(|| format!("{}{rest}", name.get(..at).unwrap_or_default()))
}

/// One line of a panel: a signal and its target, as indexes in [`Recording::signals`].
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

/// The image height when none is given: 600 pixels, or 240 per panel and 120 for the
/// title and the time axis when that is more.
fn default_height(panels: usize) -> u32 {
    let panels = u32::try_from(panels).unwrap_or(u32::MAX);
    panels
        .saturating_mul(240)
        .saturating_add(120)
        .clamp(600, 8000)
}

/// The font family all text is drawn in: the embedded `DejaVu Sans`, registered under
/// this name; SVG writes it as the `font-family`, so a viewer without it draws sans-serif.
const FAMILY: &str = "DejaVu Sans, sans-serif";

/// Registers the embedded font for bitmap text (once per process).
fn register_font() -> anyhow::Result<()> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, dejavu::sans::regular()).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(anyhow!("the embedded font could not be loaded"))
    }
}

/// Big-endian reads from a font file (`None` past its end).
fn be_u16(d: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_be_bytes([
        *d.get(at)?,
        *d.get(at.checked_add(1)?)?,
    ]))
}

fn be_i16(d: &[u8], at: usize) -> Option<i16> {
    be_u16(d, at).map(|v| i16::from_be_bytes(v.to_be_bytes()))
}

fn be_u32(d: &[u8], at: usize) -> Option<u32> {
    Some(u32::from(be_u16(d, at)?) << 16 | u32::from(be_u16(d, at.checked_add(2)?)?))
}

/// The horizontal metrics of a TrueType font, read from its tables (`head`, `hhea`,
/// `OS/2`, `cmap` format 4, `hmtx`, `kern` format 0): what laying out a line of text
/// needs. Font units; [`FontMetrics::scale`] turns them into pixels the way `ab_glyph`
/// (the rasterizer plotters uses) does: a font size is the ascender-to-descender height.
#[derive(Debug)]
pub(crate) struct FontMetrics {
    data: &'static [u8],
    /// Units per em.
    units_per_em: f32,
    /// Ascender minus descender (`hhea`): the height a font size is in pixels.
    height: f32,
    /// The height of a lowercase `x` (`OS/2`; half an em if the table lacks it).
    x_height: f32,
    /// Offset of the `cmap` subtable of format 4 (Unicode BMP).
    cmap: usize,
    /// Offset of `hmtx` and the number of its long (advance, bearing) records.
    hmtx: usize,
    long_metrics: u16,
    /// Offset of the first kerning pair and the number of pairs (`kern` format 0).
    kern: Option<(usize, usize)>,
}

impl FontMetrics {
    /// Reads the metrics of `data`; `None` if a table is missing or cut short.
    fn read(data: &'static [u8]) -> Option<Self> {
        let table = |tag: &[u8; 4]| {
            (0..usize::from(be_u16(data, 4)?)).find_map(|i| {
                let record = 12 + 16 * i;
                (data.get(record..record + 4)? == tag)
                    .then(|| usize::try_from(be_u32(data, record + 8)?).ok())
                    .flatten()
            })
        };
        let head = table(b"head")?;
        let hhea = table(b"hhea")?;
        let height = f32::from(be_i16(data, hhea + 4)?) - f32::from(be_i16(data, hhea + 6)?);
        let units_per_em = f32::from(be_u16(data, head + 18)?);
        let x_height = table(b"OS/2")
            .filter(|&os2| be_u16(data, os2).is_some_and(|version| version >= 2))
            .and_then(|os2| be_i16(data, os2 + 86))
            .map_or(units_per_em / 2.0, f32::from);
        let cmap = table(b"cmap")?;
        let cmap = (0..usize::from(be_u16(data, cmap + 2)?)).find_map(|i| {
            let record = cmap + 4 + 8 * i;
            let platform = (be_u16(data, record)?, be_u16(data, record + 2)?);
            let sub = cmap + usize::try_from(be_u32(data, record + 4)?).ok()?;
            (matches!(platform, (3, 1) | (0, 3)) && be_u16(data, sub)? == 4).then_some(sub)
        })?;
        let kern = table(b"kern").and_then(|kern| {
            let sub = kern + 4;
            let coverage = be_u16(data, sub + 4)?;
            // Format 0 (high byte), horizontal (bit 0), not cross-stream or minimum.
            (be_u16(data, kern)? == 0 && be_u16(data, kern + 2)? >= 1 && coverage & 0xff0f == 1)
                .then_some((sub + 14, usize::from(be_u16(data, sub + 6)?)))
        });
        (height > 0.0 && units_per_em > 0.0).then_some(Self {
            data,
            units_per_em,
            height,
            x_height,
            cmap,
            hmtx: table(b"hmtx")?,
            long_metrics: be_u16(data, hhea + 34)?.max(1),
            kern,
        })
    }

    /// The metrics of the embedded font.
    pub(crate) fn embedded() -> anyhow::Result<&'static Self> {
        static METRICS: OnceLock<Option<FontMetrics>> = OnceLock::new();
        METRICS
            .get_or_init(|| Self::read(dejavu::sans::regular()))
            .as_ref()
            .ok_or_else(|| anyhow!("the embedded font's metrics could not be read"))
    }

    /// Pixels per font unit at font size `size`.
    pub(crate) fn scale(&self, size: u32) -> f32 {
        // Font sizes are a few dozen pixels: exact in f32.
        #[allow(clippy::cast_precision_loss)]
        let size = size as f32;
        size / self.height
    }

    /// The glyph of `c` (0, the missing glyph, outside the BMP or the font).
    pub(crate) fn glyph(&self, c: char) -> u16 {
        self.glyph_of(u32::from(c)).unwrap_or(0)
    }

    fn glyph_of(&self, c: u32) -> Option<u16> {
        let c = u16::try_from(c).ok()?;
        let d = self.data;
        let sub = self.cmap;
        let seg_x2 = usize::from(be_u16(d, sub + 6)?);
        let seg =
            (0..seg_x2 / 2).find(|&i| be_u16(d, sub + 14 + 2 * i).is_some_and(|end| end >= c))?;
        let start = be_u16(d, sub + 16 + seg_x2 + 2 * seg)?;
        if c < start {
            return None;
        }
        let delta = be_u16(d, sub + 16 + 2 * seg_x2 + 2 * seg)?;
        let range_at = sub + 16 + 3 * seg_x2 + 2 * seg;
        let range = usize::from(be_u16(d, range_at)?);
        if range == 0 {
            return Some(c.wrapping_add(delta));
        }
        let g = be_u16(d, range_at + range + 2 * usize::from(c - start))?;
        (g != 0).then(|| g.wrapping_add(delta))
    }

    /// The advance and the left side bearing of `glyph`, font units.
    pub(crate) fn h_metrics(&self, glyph: u16) -> (f32, f32) {
        let d = self.data;
        let long = usize::from(self.long_metrics);
        let g = usize::from(glyph);
        let advance = be_u16(d, self.hmtx + 4 * g.min(long - 1)).unwrap_or(0);
        let bearing = if g < long {
            be_i16(d, self.hmtx + 4 * g + 2)
        } else {
            be_i16(d, self.hmtx + 4 * long + 2 * (g - long))
        };
        (f32::from(advance), f32::from(bearing.unwrap_or(0)))
    }

    /// The kerning between `left` and `right`, font units.
    pub(crate) fn kerning(&self, left: u16, right: u16) -> f32 {
        let Some((pairs, count)) = self.kern else {
            return 0.0;
        };
        let key = u32::from(left) << 16 | u32::from(right);
        let (mut lo, mut hi) = (0, count);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            let at = pairs + 6 * mid;
            match be_u32(self.data, at).map(|k| k.cmp(&key)) {
                Some(std::cmp::Ordering::Less) => lo = mid + 1,
                Some(std::cmp::Ordering::Greater) => hi = mid,
                Some(std::cmp::Ordering::Equal) => {
                    return be_i16(self.data, at + 4).map_or(0.0, f32::from);
                }
                None => return 0.0,
            }
        }
        0.0
    }

    /// Where each character of `text` goes: the character, its pen position and its
    /// glyph's left side bearing (font units from the start of the line); and the line's
    /// width.
    fn layout(&self, text: &str) -> (Vec<(char, f32, f32)>, f32) {
        let mut pen = 0.0;
        let mut previous = None;
        let mut glyphs = Vec::with_capacity(text.len());
        for c in text.chars() {
            let g = self.glyph(c);
            if let Some(p) = previous {
                pen += self.kerning(p, g);
            }
            let (advance, bearing) = self.h_metrics(g);
            glyphs.push((c, pen, bearing));
            pen += advance;
            previous = Some(g);
        }
        (glyphs, pen)
    }

    /// The width of `text` at font size `size`, pixels (rounded up).
    pub(crate) fn width(&self, text: &str, size: u32) -> i32 {
        px(self.layout(text).1 * self.scale(size)).saturating_add(1)
    }
}

/// A pixel coordinate from a float (saturating; plot coordinates are a few thousand).
fn px(v: f32) -> i32 {
    // Saturating by `as`, and the values are far inside i32.
    #[allow(clippy::cast_possible_truncation)]
    let v = v.floor() as i32;
    v
}

/// A line of text to draw.
#[derive(Clone, Copy)]
struct Label<'a> {
    text: &'a str,
    /// The anchor: where the line's start, middle or end ([`Label::align`]) goes, and its
    /// vertical middle (the middle of a lowercase letter).
    at: (i32, i32),
    /// Font size, pixels: an even number (plotters places a glyph's rows from half the
    /// size, rounding an odd half inconsistently).
    size: u32,
    color: RGBColor,
    align: HPos,
    /// Read upwards (a y-axis title) instead of left to right.
    upwards: bool,
}

/// Draws text on one drawing area: on a bitmap glyph by glyph, each placed at its side
/// bearing ([`FontMetrics`]); in SVG as one text element the viewer lays out.
struct Pen<'a, DB: DrawingBackend> {
    area: &'a DrawingArea<DB, Shift>,
    font: &'static FontMetrics,
    bitmap: bool,
}

impl<DB: DrawingBackend> Pen<'_, DB> {
    fn width(&self, text: &str, size: u32) -> i32 {
        self.font.width(text, size)
    }

    fn draw(&self, label: &Label<'_>) -> anyhow::Result<()> {
        let metrics = self.font;
        let scale = metrics.scale(label.size);
        let (glyphs, width) = metrics.layout(label.text);
        let start = match label.align {
            HPos::Left => 0.0,
            HPos::Center => -width * scale / 2.0,
            HPos::Right => -width * scale,
        };
        if !self.bitmap {
            // SVG: a font size of plotters' is 1.24 em; make the em the bitmap's.
            let em = f64::from(metrics.units_per_em / metrics.height);
            let style = FontDesc::new(
                FontFamily::Name(FAMILY),
                f64::from(label.size) * 1.24 * em,
                FontStyle::Normal,
            )
            .transform(if label.upwards {
                FontTransform::Rotate270
            } else {
                FontTransform::None
            })
            .color(&label.color)
            .pos(Pos::new(label.align, VPos::Center));
            return self
                .area
                .draw_text(label.text, &style, label.at)
                .map_err(|e| anyhow!("drawing failed: {e:?}"));
        }
        // plotters draws a glyph's rows from half the font size above its baseline; the
        // baseline goes half an x-height below the anchor.
        let half = i32::try_from(label.size / 2).unwrap_or(0);
        let down = px(metrics.x_height * scale / 2.0 + 0.5) - half;
        let font = FontDesc::new(
            FontFamily::Name(FAMILY),
            f64::from(label.size),
            FontStyle::Normal,
        );
        let (anchor_x, anchor_y) = label.at;
        let mut buf = [0u8; 4];
        for (c, pen, bearing) in glyphs {
            // The outline's first pixel column is where ab_glyph puts it: its bearing
            // from the pen, rounded down.
            let left = px(start + pen * scale + 0.5) + px(bearing * scale);
            let drawn = font
                .draw(c.encode_utf8(&mut buf), (0, 0), |col, row, coverage| {
                    // Along the line and down from it, then turned for upward text.
                    let (along, across) = (left + col, row + down);
                    let at = if label.upwards {
                        (anchor_x + across, anchor_y - along)
                    } else {
                        (anchor_x + along, anchor_y + across)
                    };
                    if coverage <= 0.0 {
                        return Ok(());
                    }
                    let alpha = f64::from(coverage.min(1.0));
                    self.area.draw_pixel(at, &label.color.mix(alpha))
                })
                .map_err(|e| anyhow!("the embedded font: {e}"))?;
            drawn.map_err(|e| anyhow!("drawing failed: {e:?}"))?;
        }
        Ok(())
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Png,
    Svg,
}

fn format_of(path: &Path) -> anyhow::Result<Format> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("png") => Ok(Format::Png),
        Some("svg") => Ok(Format::Svg),
        _ => Err(usage(format!(
            "--output {}: the file name must end in .png or .svg",
            path.display()
        ))),
    }
}

/// Runs `robobus plot`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    format_of(&args.output)?;
    crate::output::check_output_path(&args.output, "--output")?;
    let text = read_bounded(&args.file)?;
    let mut rec = Recording::parse(&text)
        .map_err(|e| usage(format!("{}:{}: {}", args.file.display(), e.line, e.message)))?;
    if !args.signals.is_empty() {
        for want in &args.signals {
            if !rec.signals.iter().any(|(n, _)| n == want) {
                let have: Vec<&str> = rec.signals.iter().map(|(n, _)| n.as_str()).collect();
                return Err(usage(format!(
                    "--signals: no column `{want}` in {} (columns: {})",
                    args.file.display(),
                    have.join(", ")
                )));
            }
        }
        rec.signals.retain(|(n, _)| {
            args.signals.contains(n) || target_of(n).is_some_and(|a| args.signals.contains(&a))
        });
    }
    let title = args.title.clone().unwrap_or_else(|| {
        args.file
            .file_name()
            .map_or_else(|| "recording".into(), |n| n.to_string_lossy().into_owned())
    });
    let names: Vec<&str> = rec.signals.iter().map(|(n, _)| n.as_str()).collect();
    let panels = panels(&names);
    write(&rec, &panels, &args.output, &title, args.width, args.height)?;
    if g.json {
        let panels: Vec<serde_json::Value> = panels
            .iter()
            .map(|p| {
                let name = |i: usize| names.get(i).copied();
                let series: Vec<serde_json::Value> = p
                    .series
                    .iter()
                    .map(|s| serde_json::json!({"signal": name(s.signal), "target": s.target.and_then(name)}))
                    .collect();
                serde_json::json!({"title": p.title, "series": series})
            })
            .collect();
        crate::output::print_json(&serde_json::json!({
            "output": args.output.display().to_string(),
            "rows": rec.time.len(),
            "signals": names,
            "x_title": time_title(&rec.time_name),
            "panels": panels,
        }))
    } else {
        crate::output::print(&format!(
            "wrote {} ({} rows, {} signals in {} panel{})\n",
            args.output.display(),
            rec.time.len(),
            rec.signals.len(),
            panels.len(),
            if panels.len() == 1 { "" } else { "s" }
        ))
    }
}

/// Reads the recording, refusing files over [`MAX_CSV_BYTES`] without reading further.
fn read_bounded(path: &Path) -> anyhow::Result<String> {
    use std::io::Read as _;
    // A file that is not there is bad input: exit 2, nothing drawn.
    if !path.exists() {
        return Err(usage(format!(
            "{}: no such file (give a CSV recording, e.g. from `robobus monitor --record`)",
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
    String::from_utf8(bytes).map_err(|e| {
        usage(format!(
            "{}: not UTF-8 text (byte {} is invalid)",
            path.display(),
            e.utf8_error().valid_up_to()
        ))
    })
}

/// Draws `rec` to `output` (PNG or SVG by its extension) with `title`, 1200 pixels wide
/// and as high as its panels need ([`default_height`]). For other commands that plot what
/// they recorded (`robobus demo --plot`).
pub(crate) fn write_image(rec: &Recording, output: &Path, title: &str) -> anyhow::Result<()> {
    let names: Vec<&str> = rec.signals.iter().map(|(n, _)| n.as_str()).collect();
    write(rec, &panels(&names), output, title, 1200, None)
}

/// Draws `rec` as `panels` to `output`, `width` by `height` pixels (default:
/// [`default_height`]).
fn write(
    rec: &Recording,
    panels: &[Panel],
    output: &Path,
    title: &str,
    width: u32,
    height: Option<u32>,
) -> anyhow::Result<()> {
    let format = format_of(output)?;
    register_font()?;
    let size = (
        width,
        height.unwrap_or_else(|| default_height(panels.len())),
    );
    match format {
        Format::Png => {
            let root = BitMapBackend::new(output, size).into_drawing_area();
            draw(&root, rec, panels, title, true)?;
            root.present()
                .with_context(|| format!("cannot write {}", output.display()))?;
        }
        Format::Svg => {
            let root = SVGBackend::new(output, size).into_drawing_area();
            draw(&root, rec, panels, title, false)?;
            root.present()
                .with_context(|| format!("cannot write {}", output.display()))?;
        }
    }
    Ok(())
}

/// The range of the data, widened where it is a single value or too narrow for its
/// magnitude (ticks need a span that `f64` can still subdivide).
fn span(mut lo: f64, mut hi: f64) -> (f64, f64) {
    if !lo.is_finite() || !hi.is_finite() || hi - lo > 4.0 * MAX_ABS_VALUE {
        return (0.0, 1.0);
    }
    let least = (lo.abs().max(hi.abs()) * 1e-9).max(1e-12);
    if hi - lo < least {
        let mid = lo + (hi - lo) / 2.0;
        let half = least.max(0.5 * (hi - lo)).max(0.5);
        lo = mid - half;
        hi = mid + half;
    } else {
        let pad = (hi - lo) * 0.05;
        lo -= pad;
        hi += pad;
    }
    (lo, hi)
}

/// Axis ticks from `lo` to `hi` at a step of 1, 2 or 5 times a power of ten, at most
/// `most + 1` of them, with their labels: as many decimals as the step needs, scientific
/// notation from a million or for steps below 1e-4. Also the step.
fn ticks(lo: f64, hi: f64, most: usize) -> (Vec<(f64, String)>, f64) {
    let raw = (hi - lo) / most.max(1) as f64;
    if !(raw.is_finite() && raw > 0.0) {
        return (Vec::new(), 1.0);
    }
    // |exponent| < 330 for any finite positive f64.
    #[allow(clippy::cast_possible_truncation)]
    let mut exp = raw.log10().floor() as i32;
    let mut digit = [1.0, 2.0, 5.0]
        .into_iter()
        .find(|&m| m * 10f64.powi(exp) >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0);
    if digit >= 10.0 {
        digit = 1.0;
        exp += 1;
    }
    let step = digit * 10f64.powi(exp);
    let magnitude = lo.abs().max(hi.abs());
    // f64 has 15 significant digits: no more decimals than that.
    #[allow(clippy::cast_possible_truncation)]
    let order = magnitude.log10().floor().clamp(-400.0, 400.0) as i32;
    let label = |v: f64| {
        if magnitude < 1e6 && exp >= -4 {
            let decimals = usize::try_from(-exp).unwrap_or(0);
            format!("{v:.decimals$}")
        } else {
            let decimals = usize::try_from((order - exp).clamp(0, 15)).unwrap_or(0);
            format!("{v:.decimals$e}")
        }
    };
    let first = (lo / step).ceil();
    let mut out = Vec::new();
    for n in 0..=most + 1 {
        let v = (first + n as f64) * step;
        if v > hi + step * 1e-9 {
            break;
        }
        // No `-0` label.
        let v = if v.abs() < step * 1e-9 { 0.0 } else { v };
        out.push((v, label(v)));
    }
    (out, step)
}

/// Line colours of a panel's signals, in order (the Tableau 10 palette: distinct on white
/// and for the usual colour blindness); a signal's target is drawn in its colour.
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];
const INK: RGBColor = RGBColor(34, 34, 34);
const FRAME: RGBColor = RGBColor(110, 110, 110);
const GRID: RGBColor = RGBColor(226, 226, 226);

/// Font sizes, pixels (even: see [`Label::size`]).
const TITLE_SIZE: u32 = 20;
const AXIS_SIZE: u32 = 16;
const TICK_SIZE: u32 = 14;
const LEGEND_SIZE: u32 = 14;
/// Spacing, pixels: around the figure, between panels, tick marks, legend rows, the
/// line sample in the legend, dashes of a target.
const MARGIN: i32 = 12;
const GAP: i32 = 18;
const TICK: i32 = 5;
const ROW: i32 = 20;
const SAMPLE: i32 = 28;
const DASH: (i32, i32) = (7, 5);

/// A signal's samples as line pieces: a missing sample ends a piece.
fn pieces(time: &[f64], values: &[Option<f64>]) -> Vec<Vec<(f64, f64)>> {
    let mut pieces: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (t, v) in time.iter().zip(values) {
        match (v, pieces.last_mut()) {
            (Some(v), Some(piece)) => piece.push((*t, *v)),
            (None, Some(piece)) if !piece.is_empty() => pieces.push(Vec::new()),
            _ => {}
        }
    }
    pieces.retain(|p| !p.is_empty());
    pieces
}

/// The largest font size from `size` down to 8 (even) at which `text` fits in `room`.
fn fitting<DB: DrawingBackend>(pen: &Pen<'_, DB>, text: &str, size: u32, room: i32) -> u32 {
    (4..=size / 2)
        .rev()
        .map(|half| half * 2)
        .find(|&s| pen.width(text, s) <= room)
        .unwrap_or(8)
}

/// One legend entry: text, line colour, dashed.
type Entry<'a> = (&'a str, RGBColor, bool);

/// A panel's legend laid out in columns of at most `rows`: the columns' widths.
fn legend_columns(pen_width: impl Fn(&str) -> i32, entries: &[Entry<'_>], rows: usize) -> Vec<i32> {
    entries
        .chunks(rows.max(1))
        .map(|column| {
            let text = column.iter().map(|(t, ..)| pen_width(t)).max().unwrap_or(0);
            SAMPLE + 6 + text + 14
        })
        .collect()
}

fn to_i32(v: u32) -> i32 {
    i32::try_from(v).unwrap_or(i32::MAX)
}

#[allow(clippy::too_many_lines)] // one figure: layout, then each panel
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    rec: &Recording,
    panels: &[Panel],
    title: &str,
    bitmap: bool,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let fail = |err: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing failed: {err:?}");
    let pen = Pen {
        area: root,
        font: FontMetrics::embedded()?,
        bitmap,
    };
    root.fill(&WHITE).map_err(fail)?;
    let (width, height) = root.dim_in_pixel();
    let (width, height) = (to_i32(width), to_i32(height));
    let t0 = rec.time.first().copied().unwrap_or(0.0);
    let t1 = rec.time.last().copied().unwrap_or(1.0);
    let least = (t0.abs().max(t1.abs()) * 1e-9).max(1e-12);
    let (x0, x1) = if t1 - t0 >= least && t1 - t0 <= 2.0 * MAX_ABS_VALUE {
        (t0, t1)
    } else {
        span(t0, t1)
    };
    let values = |i: usize| {
        rec.signals
            .get(i)
            .map(|(_, v)| v.as_slice())
            .unwrap_or_default()
    };
    let signal_name = |i: usize| rec.signals.get(i).map_or("", |(n, _)| n.as_str());

    // Vertical layout: the title, the panels, the time axis's labels and title.
    let title_size = fitting(&pen, title, TITLE_SIZE, width - 2 * MARGIN);
    let top = MARGIN + to_i32(title_size) + 10;
    let bottom = height - MARGIN - to_i32(AXIS_SIZE) - 8 - to_i32(TICK_SIZE) - 4 - TICK;
    let count = i32::try_from(panels.len().max(1)).unwrap_or(i32::MAX);
    let panel_h = ((bottom - top - GAP * (count - 1)) / count).max(1);

    // Each panel's value range, ticks and legend.
    let ranges: Vec<(f64, f64)> = panels
        .iter()
        .map(|p| {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for s in &p.series {
                for v in [Some(s.signal), s.target]
                    .into_iter()
                    .flatten()
                    .flat_map(|i| values(i).iter().flatten())
                {
                    lo = lo.min(*v);
                    hi = hi.max(*v);
                }
            }
            span(lo, hi)
        })
        .collect();
    let most_y = usize::try_from(panel_h / 40).unwrap_or(1).max(1);
    let y_ticks: Vec<Vec<(f64, String)>> = ranges
        .iter()
        .map(|&(lo, hi)| ticks(lo, hi, most_y).0)
        .collect();
    let legends: Vec<Vec<Entry<'_>>> = panels
        .iter()
        .map(|p| {
            let mut entries: Vec<Entry<'_>> = p
                .series
                .iter()
                .zip(PALETTE.iter().cycle())
                .map(|(s, &c)| (signal_name(s.signal), c, false))
                .collect();
            if p.series.iter().any(|s| s.target.is_some()) {
                entries.push(("target", INK, true));
            }
            entries
        })
        .collect();
    let rows = usize::try_from((panel_h - 4) / ROW).unwrap_or(1).max(1);
    let legend_w = legends
        .iter()
        .map(|l| {
            legend_columns(|t| pen.width(t, LEGEND_SIZE), l, rows)
                .iter()
                .sum::<i32>()
        })
        .max()
        .unwrap_or(0)
        .min(width / 3);

    // Horizontal layout: the y titles, tick labels, the panels, the legends.
    let tick_w = y_ticks
        .iter()
        .flatten()
        .map(|(_, l)| pen.width(l, TICK_SIZE))
        .max()
        .unwrap_or(0);
    let left = MARGIN + to_i32(AXIS_SIZE) + 10 + tick_w + 4 + TICK;
    let right = (width - MARGIN - legend_w).max(left + 1);
    let plot_w = right - left;
    // As many time ticks as their labels leave room for.
    let mut most_x = usize::try_from(plot_w / 80).unwrap_or(1).max(1);
    let x_ticks = loop {
        let (t, step) = ticks(x0, x1, most_x);
        let widest = t
            .iter()
            .map(|(_, l)| pen.width(l, TICK_SIZE))
            .max()
            .unwrap_or(0);
        let spacing = f64::from(plot_w) * step / (x1 - x0);
        if f64::from(widest + 16) <= spacing || most_x == 1 {
            break t;
        }
        most_x -= 1;
    };

    for (index, ((panel, &(y0, y1)), (yt, legend))) in panels
        .iter()
        .zip(&ranges)
        .zip(y_ticks.iter().zip(&legends))
        .enumerate()
    {
        let index = i32::try_from(index).unwrap_or(i32::MAX);
        let y_top = top + index * (panel_h + GAP);
        let area = root.clone().shrink(
            (left, y_top),
            (plot_w.unsigned_abs(), panel_h.unsigned_abs()),
        );
        let mut chart = ChartBuilder::on(&area)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(fail)?;
        for (x, _) in &x_ticks {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(*x, y0), (*x, y1)],
                    GRID,
                )))
                .map_err(fail)?;
        }
        for (y, _) in yt {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(x0, *y), (x1, *y)],
                    GRID,
                )))
                .map_err(fail)?;
        }
        for (s, &color) in panel.series.iter().zip(PALETTE.iter().cycle()) {
            if let Some(target) = s.target {
                for piece in pieces(&rec.time, values(target)) {
                    chart
                        .draw_series(DashedLineSeries::new(
                            piece,
                            DASH.0,
                            DASH.1,
                            color.stroke_width(2),
                        ))
                        .map_err(fail)?;
                }
            }
            for piece in pieces(&rec.time, values(s.signal)) {
                chart
                    .draw_series(LineSeries::new(piece, color.stroke_width(2)))
                    .map_err(fail)?;
            }
            // A sample alone between gaps makes no line: a dot.
            for piece in [Some(s.signal), s.target]
                .into_iter()
                .flatten()
                .flat_map(|i| pieces(&rec.time, values(i)))
                .filter(|p| p.len() == 1)
            {
                chart
                    .draw_series(piece.into_iter().map(|p| Circle::new(p, 2, color.filled())))
                    .map_err(fail)?;
            }
        }
        let y_bottom = y_top + panel_h;
        root.draw(&Rectangle::new([(left, y_top), (right, y_bottom)], FRAME))
            .map_err(fail)?;
        for (y, label) in yt {
            let (_, py) = chart.backend_coord(&(x0, *y));
            root.draw(&PathElement::new(
                vec![(left - TICK, py), (left, py)],
                FRAME,
            ))
            .map_err(fail)?;
            pen.draw(&Label {
                text: label,
                at: (left - TICK - 4, py),
                size: TICK_SIZE,
                color: INK,
                align: HPos::Right,
                upwards: false,
            })?;
        }
        pen.draw(&Label {
            text: &panel.title,
            at: (MARGIN + to_i32(AXIS_SIZE) / 2, y_top + panel_h / 2),
            size: fitting(&pen, &panel.title, AXIS_SIZE, panel_h + GAP - 4),
            color: INK,
            align: HPos::Center,
            upwards: true,
        })?;
        // The legend, beside the panel: columns of `rows` entries.
        let mut column_x = right + 14;
        let widths = legend_columns(|t| pen.width(t, LEGEND_SIZE), legend, rows);
        for (column, column_w) in legend.chunks(rows).zip(widths) {
            for (row, &(text, color, dashed)) in column.iter().enumerate() {
                let row = i32::try_from(row).unwrap_or(i32::MAX);
                let y = y_top + 2 + ROW / 2 + row * ROW;
                let line = vec![(column_x, y), (column_x + SAMPLE, y)];
                if dashed {
                    root.draw(&DashedPathElement::new(
                        line,
                        DASH.0,
                        DASH.1,
                        color.stroke_width(2),
                    ))
                    .map_err(fail)?;
                } else {
                    root.draw(&PathElement::new(line, color.stroke_width(2)))
                        .map_err(fail)?;
                }
                pen.draw(&Label {
                    text,
                    at: (column_x + SAMPLE + 6, y),
                    size: LEGEND_SIZE,
                    color: INK,
                    align: HPos::Left,
                    upwards: false,
                })?;
            }
            column_x += column_w;
        }
        // The time axis: ticks on every panel, labels under the last.
        let lowest = index + 1 == count;
        for (t, label) in &x_ticks {
            let (px, _) = chart.backend_coord(&(*t, y0));
            root.draw(&PathElement::new(
                vec![(px, y_bottom), (px, y_bottom + TICK)],
                FRAME,
            ))
            .map_err(fail)?;
            if lowest {
                pen.draw(&Label {
                    text: label,
                    at: (px, y_bottom + TICK + 4 + to_i32(TICK_SIZE) / 2),
                    size: TICK_SIZE,
                    color: INK,
                    align: HPos::Center,
                    upwards: false,
                })?;
            }
        }
    }
    let time = time_title(&rec.time_name);
    pen.draw(&Label {
        text: &time,
        at: (
            i32::midpoint(left, right),
            height - MARGIN - to_i32(AXIS_SIZE) / 2,
        ),
        size: fitting(&pen, &time, AXIS_SIZE, plot_w),
        color: INK,
        align: HPos::Center,
        upwards: false,
    })?;
    pen.draw(&Label {
        text: title,
        at: (width / 2, MARGIN + to_i32(title_size) / 2),
        size: title_size,
        color: INK,
        align: HPos::Center,
        upwards: false,
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_header_rows_and_gaps() {
        let r = Recording::parse("# c\nt_s,a,b\n0,1,\n0.5,2,3\n").unwrap();
        assert_eq!(r.time_name, "t_s");
        assert_eq!(r.time, [0.0, 0.5]);
        assert_eq!(r.signals[0], ("a".into(), vec![Some(1.0), Some(2.0)]));
        assert_eq!(r.signals[1], ("b".into(), vec![None, Some(3.0)]));
    }

    #[test]
    fn values_and_lines_are_bounded() {
        let e = Recording::parse("t,a\n0,1\n1,-1e308\n").unwrap_err();
        assert_eq!(e.line, 3);
        assert!(e.message.contains("-1e12..=1e12"), "{}", e.message);
        assert!(Recording::parse("t,a\n0,1e12\n1,-1e12\n").is_ok());
        let long = format!("t,a\n0,{}\n", "1".repeat(MAX_LINE_BYTES));
        let e = Recording::parse(&long).unwrap_err();
        assert_eq!(e.line, 2);
        assert!(e.message.contains("64 KiB"), "{}", e.message);
        // Spans are widened to something f64 can subdivide.
        let (lo, hi) = span(1e12, 1e12);
        assert!(hi - lo >= 1e3 && lo < 1e12 && hi > 1e12);
        assert_eq!(span(f64::NEG_INFINITY, 1.0), (0.0, 1.0));
    }

    #[test]
    fn errors_name_the_line() {
        let e = Recording::parse("t,a\n0,1\n1,x\n").unwrap_err();
        assert_eq!(e.line, 3);
        assert!(e.message.contains("`x`"), "{}", e.message);
        assert_eq!(Recording::parse("t,a\n0,1,2\n").unwrap_err().line, 2);
        assert_eq!(Recording::parse("t,a\n1,1\n0,1\n").unwrap_err().line, 3);
        assert_eq!(Recording::parse("t\n").unwrap_err().line, 1);
        assert!(Recording::parse("t,a\n").is_err());
        assert!(Recording::parse("").is_err());
    }

    fn series(signal: usize, target: Option<usize>) -> Series {
        Series { signal, target }
    }

    fn panel(title: &str, series: &[Series]) -> Panel {
        Panel {
            title: title.into(),
            series: series.to_vec(),
        }
    }

    #[test]
    fn the_demo_trace_is_one_panel_per_family_with_targets() {
        let names = robobus::demo::Trace::names();
        assert_eq!(
            panels(&names),
            [
                panel(
                    "wCK servo angle (deg)",
                    &[
                        series(0, Some(11)),
                        series(1, Some(12)),
                        series(2, Some(13)),
                        series(3, Some(14)),
                    ]
                ),
                panel(
                    "WHJ joint angle (deg)",
                    &(4..11).map(|i| series(i, Some(i + 11))).collect::<Vec<_>>()
                ),
            ]
        );
    }

    #[test]
    fn monitor_recordings_are_one_panel_per_unit() {
        // `robobus monitor` on a WHJ bus, a wCK port, a robot file.
        let whj = ["j1_deg", "j1_rpm", "j1_mA", "j2_deg", "j2_rpm", "j2_mA"];
        assert_eq!(
            panels(&whj),
            [
                panel("WHJ joint angle (deg)", &[series(0, None), series(3, None)]),
                panel("WHJ joint speed (rpm)", &[series(1, None), series(4, None)]),
                panel(
                    "WHJ joint current (mA)",
                    &[series(2, None), series(5, None)]
                ),
            ]
        );
        let wck = [
            "s0_deg",
            "s0_deg_per_s",
            "s0_load",
            "s1_deg",
            "s1_deg_per_s",
            "s1_load",
        ];
        assert_eq!(
            panels(&wck),
            [
                panel("wCK servo angle (deg)", &[series(0, None), series(3, None)]),
                panel(
                    "wCK servo speed (deg/s)",
                    &[series(1, None), series(4, None)]
                ),
                panel("wCK servo load", &[series(2, None), series(5, None)]),
            ]
        );
        let robot = [
            "left_knee_deg",
            "left_knee_deg_per_s",
            "left_knee_load",
            "shoulder_1_deg",
            "shoulder_1_deg_per_s",
            "shoulder_1_mA",
        ];
        assert_eq!(
            panels(&robot),
            [
                panel("angle (deg)", &[series(0, None), series(3, None)]),
                panel("speed (deg/s)", &[series(1, None), series(4, None)]),
                panel("load", &[series(2, None)]),
                panel("current (mA)", &[series(5, None)]),
            ]
        );
        // Other spellings of the families and units; names without a unit.
        let other = [
            "servo3_deg",
            "wck_hip_rad",
            "joint2_rad_s",
            "WHJ4_DEG_S",
            "a",
            "b",
        ];
        assert_eq!(
            panels(&other),
            [
                panel("wCK servo angle (deg)", &[series(0, None)]),
                panel("wCK servo angle (rad)", &[series(1, None)]),
                panel("WHJ joint speed (rad/s)", &[series(2, None)]),
                panel("WHJ joint speed (deg/s)", &[series(3, None)]),
                panel("value", &[series(4, None), series(5, None)]),
            ]
        );
    }

    #[test]
    fn targets_pair_with_their_signals() {
        let names = [
            "j1_deg",
            "j1_target_deg", // j1_deg's target
            "j2_deg_target", // j2_deg's target, before it
            "j2_deg",
            "j9_target_deg", // no j9_deg: a line of its own, in j9_deg's panel
            "a",
            "a_target",      // a's target
            "a_targets",     // not a target's name
            "j1_deg_target", // a second target of j1_deg: a line of its own
            "J1_TARGET_DEG", // names are compared exactly: no `J1_DEG`
        ];
        assert_eq!(target_of("j1_target_deg").as_deref(), Some("j1_deg"));
        assert_eq!(target_of("j2_deg_target").as_deref(), Some("j2_deg"));
        assert_eq!(target_of("a_targets"), None);
        assert_eq!(target_of("_target"), None);
        assert_eq!(
            panels(&names),
            [
                panel(
                    "WHJ joint angle (deg)",
                    &[
                        series(0, Some(1)),
                        series(3, Some(2)),
                        series(4, None),
                        series(8, None),
                        series(9, None),
                    ]
                ),
                panel("value", &[series(5, Some(6)), series(7, None)]),
            ]
        );
    }

    #[test]
    fn the_time_axis_is_titled_with_its_unit() {
        for (name, title) in [
            ("t_s", "time (s)"),
            ("T_S", "time (s)"),
            ("time_ms", "time (ms)"),
            ("t_us", "time (µs)"),
            ("elapsed_min", "elapsed (min)"),
            ("t", "time"),
            ("stamp", "stamp"),
            ("_s", "_s"),
        ] {
            assert_eq!(time_title(name), title, "{name}");
        }
        assert_eq!(default_height(1), 600);
        assert_eq!(default_height(2), 600);
        assert_eq!(default_height(3), 840);
        assert_eq!(default_height(1000), 8000);
    }

    #[test]
    fn ticks_step_by_one_two_five() {
        let labels = |lo, hi, most| -> Vec<String> {
            ticks(lo, hi, most).0.into_iter().map(|(_, l)| l).collect()
        };
        assert_eq!(labels(0.0, 10.0, 5), ["0", "2", "4", "6", "8", "10"]);
        assert_eq!(
            labels(-0.35, 1.05, 7),
            ["-0.2", "0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]
        );
        assert_eq!(labels(-52.0, 83.0, 3), ["-50", "0", "50"]);
        assert_eq!(
            labels(0.0, 2e12, 4),
            ["0.0e0", "5.0e11", "1.0e12", "1.5e12", "2.0e12"]
        );
        assert!((ticks(0.0, 1.0, 4).1 - 0.5).abs() < 1e-12);
        assert!(ticks(1.0, 1.0, 4).0.is_empty());
    }

    #[test]
    fn font_metrics_are_the_fonts_and_match_plotters_widths() {
        let f = FontMetrics::embedded().unwrap();
        // DejaVu Sans: advance and left side bearing, font units.
        for (c, metrics) in [
            ('1', (1303.0, 225.0)),
            ('j', (569.0, -37.0)),
            ('_', (1024.0, -20.0)),
            ('h', (1298.0, 186.0)),
        ] {
            assert_eq!(f.h_metrics(f.glyph(c)), metrics, "{c:?}");
        }
        assert_eq!(f.glyph('\u{10000}'), 0);
        // Widths with kerning (`AV`, `To`) as plotters (ab_glyph) measures them.
        register_font().unwrap();
        for text in ["whj1_deg", "WHJ joint angle (deg)", "AVATAR To -40.5 µs °"] {
            for size in [14, 16, 20] {
                let font =
                    FontDesc::new(FontFamily::Name(FAMILY), f64::from(size), FontStyle::Normal);
                let ((x0, _), (x1, _)) = font.layout_box(text).unwrap();
                assert_eq!(
                    px(f.layout(text).1 * f.scale(size)),
                    x1 - x0,
                    "{text:?} at {size}"
                );
            }
        }
        assert!(f.kerning(f.glyph('A'), f.glyph('V')) < 0.0);
    }

    /// The ink of `label` drawn on a white bitmap: per column, whether any pixel is not
    /// white.
    fn ink_columns(draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>)) -> Vec<bool> {
        let (w, h) = (300u32, 40u32);
        let mut buf = vec![0u8; 3 * 300 * 40];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            root.fill(&WHITE).unwrap();
            draw(&root);
            root.present().unwrap();
        }
        (0..300)
            .map(|x| (0..40).any(|y| buf[3 * (y * 300 + x)..][..3] != [255, 255, 255]))
            .collect()
    }

    /// The first and last inked column, and the blank ones between.
    fn blanks(ink: &[bool]) -> (usize, usize, Vec<usize>) {
        let first = ink.iter().position(|&i| i).unwrap();
        let last = ink.iter().rposition(|&i| i).unwrap();
        let blank = (first..=last).filter(|&x| !ink[x]).collect();
        (first, last, blank)
    }

    #[test]
    fn bitmap_labels_keep_the_fonts_spacing() {
        register_font().unwrap();
        let font = FontMetrics::embedded().unwrap();
        let pen = |text: &'static str| {
            move |root: &DrawingArea<BitMapBackend<'_>, Shift>| {
                let label = Label {
                    text,
                    at: (10, 20),
                    size: 14,
                    color: BLACK,
                    align: HPos::Left,
                    upwards: false,
                };
                Pen {
                    area: root,
                    font,
                    bitmap: true,
                }
                .draw(&label)
                .unwrap();
            }
        };
        let plotters = |text: &'static str| {
            move |root: &DrawingArea<BitMapBackend<'_>, Shift>| {
                let style = (FAMILY, 14).into_font().color(&BLACK);
                root.draw_text(text, &style, (10, 20)).unwrap();
            }
        };
        // A glyph's ink starts at its left side bearing from the pen: 225 units (1.3 px at
        // 14 px) for `1`, -37 (-0.2 px) for `j`. plotters' own bitmap text starts it at the
        // pen. (When plotters places glyphs right, `Pen` can draw its text directly.)
        assert_eq!(blanks(&ink_columns(pen("1"))).0, 11);
        assert_eq!(blanks(&ink_columns(pen("j"))).0, 9);
        assert_eq!(blanks(&ink_columns(plotters("1"))).0, 10);
        // `whj1_deg` at 14 px: each glyph's box (DejaVu Sans: xMin..xMax w 86..1589,
        // h 186..1124, j -37..377, 1 225..1114, _ -20..1044, d 113..1114, e 113..1151,
        // g 113..1114) from its pen position (the advances: 1675, 1298, 569, 1303, 1024,
        // 1300, 1260) ink columns 10..=19, 21..=26, 26..=29, 32..=37, 37..=44, 44..=50,
        // 52..=58, 59..=65: blank are 20, 30, 31 and 51.
        assert_eq!(
            blanks(&ink_columns(pen("whj1_deg"))),
            (10, 65, vec![20, 30, 31, 51])
        );
        // plotters: `wh j1 _deg`.
        assert_ne!(
            blanks(&ink_columns(plotters("whj1_deg"))).2,
            vec![20, 30, 31, 51]
        );
    }
}
