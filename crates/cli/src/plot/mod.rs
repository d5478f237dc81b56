//! `robobus plot`: plot a recording (CSV, or the samples of an MCAP recording) to a PNG
//! or SVG file.
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
//! ([`panels`](fn@panels)), read from the column names: the unit from the suffix (`_deg`,
//! `_rpm`, `_mA`, ...), the family from the prefix (`wck3` / `s3`: wCK servos, `whj1` / `j1`: WHJ
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
//! next one and labels read `wh j1 _deg`. So this module lays text out itself
//! ([`Pen`](text::Pen)): each glyph's outline is rasterized by plotters but placed at the
//! pen plus its side bearing, from the font's own tables
//! ([`FontMetrics`](text::FontMetrics)).
//!
//! # Modules
//!
//! - [`recording`]: the CSV recording, an MCAP recording's samples, and reading either, bounded.
//! - [`panels`](mod@panels): the grouping of signals into panels, and the axis titles.
//! - [`text`]: text laid out from the embedded font's metrics.
//! - [`draw`]: the figure, drawn to PNG or SVG.

mod draw;
mod panels;
mod recording;
mod text;

#[cfg(test)]
mod tests;

use std::path::PathBuf;

use crate::Global;
use crate::exit::usage;

pub(crate) use draw::write_image;
pub(crate) use panels::time_title;
pub(crate) use recording::Recording;

use draw::{format_of, write};
use panels::{panels, target_of};
use recording::{read_bounded, read_bytes_bounded};

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
A file ending in .mcap is read as `robobus monitor --record FILE.mcap` writes it: the
samples on /robobus/samples, as the columns the CSV would have.
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
    /// The recording: CSV (see below), or MCAP from `robobus monitor --record FILE.mcap`
    /// (its samples, as the same columns).
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

/// Runs `robobus plot`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    format_of(&args.output)?;
    crate::output::check_output_path(&args.output, "--output")?;
    let mut rec = if args.file.extension().is_some_and(|e| e == "mcap") {
        let bytes = read_bytes_bounded(&args.file)?;
        Recording::from_mcap(&bytes).map_err(|e| usage(format!("{}: {e}", args.file.display())))?
    } else {
        let text = read_bounded(&args.file)?;
        Recording::parse(&text)
            .map_err(|e| usage(format!("{}:{}: {}", args.file.display(), e.line, e.message)))?
    };
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
