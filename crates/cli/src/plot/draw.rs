//! The figure: the output's format, the layout of the panels, their axes, ticks, lines and
//! legends, drawn to PNG or SVG ([`write`](fn@write)).

use std::path::Path;

use anyhow::{Context as _, anyhow};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::HPos;

use super::panels::{Panel, panels, time_title};
use super::recording::{MAX_ABS_VALUE, Recording};
use super::text::{FontMetrics, Label, Pen, register_font};
use crate::exit::usage;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Format {
    Png,
    Svg,
}

pub(super) fn format_of(path: &Path) -> anyhow::Result<Format> {
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

/// The image height when none is given: 600 pixels, or 240 per panel and 120 for the
/// title and the time axis when that is more.
pub(super) fn default_height(panels: usize) -> u32 {
    let panels = u32::try_from(panels).unwrap_or(u32::MAX);
    panels
        .saturating_mul(240)
        .saturating_add(120)
        .clamp(600, 8000)
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
pub(super) fn write(
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
pub(super) fn span(mut lo: f64, mut hi: f64) -> (f64, f64) {
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
pub(super) fn ticks(lo: f64, hi: f64, most: usize) -> (Vec<(f64, String)>, f64) {
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
