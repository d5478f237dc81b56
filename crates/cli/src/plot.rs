//! `robobus plot`: plot a recording (CSV) to a PNG or SVG file.
//!
//! # Recording format
//!
//! [`FORMAT_HELP`]: plain CSV, comma-separated, no quoting; the first non-comment line is
//! the header, the first column is time, every other column is one signal. An empty cell
//! is a missing sample. `robobus monitor` writes this format.
//!
//! ```text
//! t_s,j1_deg,j1_mA
//! 0.000,0.0,12
//! 0.002,0.1,15
//! ```
//!
//! PNG text is drawn with `DejaVu Sans`, embedded in the binary (crate `dejavu`), so plots
//! look the same on a machine without fonts; SVG names the font family and lets the
//! viewer draw the text.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::Global;
use crate::exit::usage;

/// `--help` text describing the CSV format.
pub(crate) const FORMAT_HELP: &str = "\
Recording format (CSV, what `robobus monitor` writes):
  * comma-separated, no quoting; lines starting with `#` and blank lines are ignored
  * the first line is the header: the time column first (its name is the x-axis label,
    e.g. `t_s` or `time_ms`), then one column per signal (`j1_deg`, `servo3_pos`, ...)
  * every further line: a time and one number per signal; an empty cell is a missing
    sample; times must not decrease
  * limits: numbers within ±1e12, lines up to 64 KiB, files up to 64 MiB
Example:
  t_s,j1_deg,j1_mA
  0.000,0.0,12
  0.002,0.1,15";

/// Options of `robobus plot`.
#[derive(Debug, clap::Args)]
#[command(after_help = FORMAT_HELP)]
pub(crate) struct Args {
    /// The recording (CSV, see below).
    file: PathBuf,
    /// Output file; the format follows the extension: .png or .svg.
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
    /// Only these signals (column names, comma-separated); default all.
    #[arg(long, value_delimiter = ',')]
    signals: Vec<String>,
    /// Title (default: the file name).
    #[arg(long)]
    title: Option<String>,
    /// Image width in pixels (200..=8000).
    #[arg(long, default_value_t = 1200, value_parser = clap::value_parser!(u32).range(200..=8000))]
    width: u32,
    /// Image height in pixels (150..=8000).
    #[arg(long, default_value_t = 600, value_parser = clap::value_parser!(u32).range(150..=8000))]
    height: u32,
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

/// Registers the embedded font for bitmap text (once per process).
fn register_font() -> anyhow::Result<()> {
    static DONE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(anyhow!("the embedded font could not be loaded"))
    }
}

/// Runs `robobus plot`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    let format = format_of(&args.output)?;
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
        rec.signals.retain(|(n, _)| args.signals.contains(n));
    }
    let title = args.title.clone().unwrap_or_else(|| {
        args.file
            .file_name()
            .map_or_else(|| "recording".into(), |n| n.to_string_lossy().into_owned())
    });
    let size = (args.width, args.height);
    // Both backends measure text with the font; PNG also draws it.
    register_font()?;
    match format {
        Format::Png => {
            let root = BitMapBackend::new(&args.output, size).into_drawing_area();
            draw(&root, &rec, &title)?;
            root.present()
                .with_context(|| format!("cannot write {}", args.output.display()))?;
        }
        Format::Svg => {
            let root = SVGBackend::new(&args.output, size).into_drawing_area();
            draw(&root, &rec, &title)?;
            root.present()
                .with_context(|| format!("cannot write {}", args.output.display()))?;
        }
    }
    if g.json {
        crate::output::print_json(&serde_json::json!({
            "output": args.output.display().to_string(),
            "rows": rec.time.len(),
            "signals": rec.signals.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>(),
        }))
    } else {
        crate::output::print(&format!(
            "wrote {} ({} rows, {} signals)\n",
            args.output.display(),
            rec.time.len(),
            rec.signals.len()
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

/// Draws `rec` to `output` (PNG or SVG by its extension) with `title`, 1200 x 600 pixels.
/// For other commands that plot what they recorded (`robobus demo --plot`).
pub(crate) fn write_image(rec: &Recording, output: &Path, title: &str) -> anyhow::Result<()> {
    let format = format_of(output)?;
    register_font()?;
    let size = (1200, 600);
    match format {
        Format::Png => {
            let root = BitMapBackend::new(output, size).into_drawing_area();
            draw(&root, rec, title)?;
            root.present()
                .with_context(|| format!("cannot write {}", output.display()))?;
        }
        Format::Svg => {
            let root = SVGBackend::new(output, size).into_drawing_area();
            draw(&root, rec, title)?;
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

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    rec: &Recording,
    title: &str,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let e = |err: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing failed: {err:?}");
    root.fill(&WHITE).map_err(e)?;
    let t0 = rec.time.first().copied().unwrap_or(0.0);
    let t1 = rec.time.last().copied().unwrap_or(1.0);
    let least = (t0.abs().max(t1.abs()) * 1e-9).max(1e-12);
    let (x0, x1) = if t1 - t0 >= least && t1 - t0 <= 2.0 * MAX_ABS_VALUE {
        (t0, t1)
    } else {
        span(t0, t1)
    };
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in rec.signals.iter().flat_map(|(_, v)| v.iter().flatten()) {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    let (y0, y1) = span(lo, hi);
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(rec.time_name.as_str())
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(e)?;
    for (i, (name, values)) in rec.signals.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        // Missing samples split a signal into separate line pieces.
        let mut pieces: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for (t, v) in rec.time.iter().zip(values) {
            match (v, pieces.last_mut()) {
                (Some(v), Some(piece)) => piece.push((*t, *v)),
                (None, Some(piece)) if !piece.is_empty() => pieces.push(Vec::new()),
                _ => {}
            }
        }
        let mut first = true;
        for piece in pieces.into_iter().filter(|p| !p.is_empty()) {
            let series = chart
                .draw_series(LineSeries::new(piece, color.stroke_width(2)))
                .map_err(e)?;
            if first {
                series
                    .label(name.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
                first = false;
            }
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(e)?;
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
}
