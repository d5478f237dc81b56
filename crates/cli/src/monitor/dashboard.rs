//! The dashboard: each watched device's latest values and history, and how a frame is drawn.

use std::collections::VecDeque;
use std::fmt::Write as _;

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Style, Stylize as _};
use ratatui::symbols::Marker;
use ratatui::text::Line;
use ratatui::widgets::{Axis, Block, Cell, Chart, Dataset, GraphType, Paragraph, Row, Table};

use super::WINDOW_S;

/// One watched device's latest values and history.
#[derive(Debug, Clone, Default)]
pub(crate) struct Channel {
    /// Label, e.g. `J3` or `S12`.
    pub(crate) name: String,
    /// Position, degrees.
    pub(crate) position: Option<f64>,
    /// Speed (RPM for WHJ, degrees/s for wCK).
    pub(crate) speed: Option<f64>,
    /// Current in mA (WHJ) or load (wCK, 0..=255).
    pub(crate) effort: Option<f64>,
    /// Unit of `effort`: `mA` (WHJ) or `load` (wCK).
    pub(crate) effort_unit: &'static str,
    /// Drive enabled (WHJ).
    pub(crate) enabled: Option<bool>,
    /// Error text of the latest sample (`no error`, an error bit list, `timeout`).
    pub(crate) error: String,
    /// Failed samples.
    pub(crate) failures: u64,
    /// The latest sample answered (`false`: the values shown are older, stale).
    pub(crate) fresh: bool,
    /// Samples answered in all.
    pub(crate) answered: u64,
    /// (time, position) for the plot.
    pub(crate) history: VecDeque<(f64, f64)>,
}

impl Channel {
    /// The device answered this sample.
    pub(super) fn got(&mut self) {
        self.fresh = true;
        self.answered += 1;
    }

    /// The device did not answer this sample: its values are stale from now on.
    pub(super) fn missed(&mut self, why: &str) {
        self.fresh = false;
        self.failures += 1;
        why.clone_into(&mut self.error);
    }

    /// `value` if this sample answered, else `None` (never an older value as this one).
    fn now(&self, value: Option<f64>) -> Option<f64> {
        value.filter(|_| self.fresh)
    }
}

/// What the dashboard shows.
#[derive(Debug, Clone, Default)]
pub(crate) struct Dashboard {
    /// Top line: the source.
    pub(crate) title: String,
    /// Speed column unit.
    pub(crate) speed_unit: &'static str,
    /// Effort column header (`current mA` / `load`).
    pub(crate) effort_name: &'static str,
    /// The devices.
    pub(crate) channels: Vec<Channel>,
    /// Seconds since the start.
    pub(crate) t: f64,
    /// Samples taken.
    pub(crate) samples: u64,
    /// Where samples are recorded.
    pub(crate) recording: Option<String>,
    /// Channels are a robot file's joints (named), not device IDs.
    pub(crate) named_joints: bool,
    /// Samples of the stream the monitor lost (it fell behind by a whole queue).
    pub(crate) lost: u64,
    /// The latest sample's read started more than one period after its slot.
    pub(crate) late: bool,
}

impl Dashboard {
    pub(super) fn push_history(&mut self) {
        let t = self.t;
        for c in &mut self.channels {
            if let Some(p) = c.position {
                c.history.push_back((t, p));
            }
            while c.history.front().is_some_and(|(t0, _)| *t0 < t - WINDOW_S) {
                c.history.pop_front();
            }
        }
    }

    pub(super) fn csv_header(&self) -> String {
        let mut s = String::from("t_s");
        let speed = self.speed_unit.replace('/', "_per_").to_ascii_lowercase();
        for c in &self.channels {
            let n = column_name(&c.name);
            let _ = write!(s, ",{n}_deg,{n}_{speed},{n}_{}", c.effort_unit);
        }
        s
    }

    /// One sample as a JSON object (`robobus --json monitor` prints one per line).
    pub(super) fn json_line(&self) -> String {
        let speed_key = format!(
            "speed_{}",
            self.speed_unit.replace('/', "_per_").to_ascii_lowercase()
        );
        let channels: Vec<serde_json::Value> = self
            .channels
            .iter()
            .map(|c| {
                let mut o = serde_json::Map::new();
                o.insert("name".into(), c.name.clone().into());
                o.insert("position_deg".into(), c.now(c.position).into());
                o.insert(speed_key.clone(), c.now(c.speed).into());
                let effort_key = if c.effort_unit == "mA" {
                    "current_ma"
                } else {
                    "load"
                };
                o.insert(effort_key.into(), c.now(c.effort).into());
                o.insert("enabled".into(), c.enabled.filter(|_| c.fresh).into());
                o.insert("error".into(), c.error.clone().into());
                o.insert("failures".into(), c.failures.into());
                // A missing sample: its values are null, never the last good ones.
                o.insert("stale".into(), (!c.fresh).into());
                serde_json::Value::Object(o)
            })
            .collect();
        serde_json::json!({
            "t_s": (self.t * 1e4).round() / 1e4,
            "sample": self.samples,
            "late": self.late,
            "lost": self.lost,
            "channels": channels,
        })
        .to_string()
    }

    pub(super) fn csv_row(&self) -> String {
        let mut s = format!("{:.4}", self.t);
        let cell = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v:.4}"));
        for c in &self.channels {
            let _ = write!(
                s,
                ",{},{},{}",
                cell(c.now(c.position)),
                cell(c.now(c.speed)),
                cell(c.now(c.effort))
            );
        }
        s
    }

    pub(super) fn plain_line(&self) -> String {
        let mut s = format!("t={:6.2}s", self.t);
        for c in &self.channels {
            match c.now(c.position) {
                Some(p) => {
                    let _ = write!(s, "  {} {p:8.3}", c.name);
                }
                None => {
                    let _ = write!(s, "  {} {:>8}", c.name, c.error);
                }
            }
        }
        s
    }
}

/// A channel name as a CSV column prefix: lower case, anything but letters, digits and
/// `_` replaced by `_` (joint names of a robot file are free text).
fn column_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect()
}

/// Line colours of the plot, one per channel (repeating).
const COLORS: [Color; 8] = [
    Color::Cyan,
    Color::Yellow,
    Color::Magenta,
    Color::Green,
    Color::Red,
    Color::Blue,
    Color::White,
    Color::LightRed,
];

/// Draws the dashboard: header, table, position plot.
#[allow(clippy::too_many_lines)] // one widget after the other
pub(crate) fn render(f: &mut Frame<'_>, d: &Dashboard) {
    let rows = u16::try_from(d.channels.len()).unwrap_or(30);
    let [head, table, plot, foot] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Length(rows + 3),
        Constraint::Min(6),
        Constraint::Length(1),
    ])
    .areas(f.area());
    f.render_widget(
        Paragraph::new(Line::from(vec![
            "robobus monitor ".bold(),
            d.title.clone().into(),
            format!("   t = {:.1} s, {} samples", d.t, d.samples).into(),
            if d.lost > 0 {
                format!(", {} not shown (the terminal fell behind)", d.lost).yellow()
            } else {
                "".into()
            },
        ])),
        head,
    );
    let cell =
        |v: Option<f64>, prec: usize| v.map_or_else(|| "-".into(), |v| format!("{v:.prec$}"));
    let name_width = d
        .channels
        .iter()
        .map(|c| c.name.chars().count())
        .max()
        .unwrap_or(0)
        .clamp(4, 24);
    let name_width = u16::try_from(name_width + 1).unwrap_or(25);
    let body = d.channels.iter().map(|c| {
        let en = match c.enabled {
            Some(true) => "on",
            Some(false) => "off",
            None => "-",
        };
        let err_style = if c.error == "no error" || c.error == "ok" {
            Style::default().fg(Color::Green)
        } else {
            Style::default().fg(Color::Red)
        };
        // A missing sample shows the last values dimmed and marked stale.
        let value_style = if c.fresh {
            Style::default()
        } else {
            Style::default().fg(Color::DarkGray)
        };
        let stale = if c.fresh { "" } else { " stale" };
        #[allow(clippy::cast_precision_loss)] // sample counts
        let loss = if d.samples > 0 {
            format!(
                "{} ({:.0}%)",
                c.failures,
                100.0 * c.failures as f64 / d.samples as f64
            )
        } else {
            c.failures.to_string()
        };
        Row::new(vec![
            Cell::from(c.name.clone()),
            Cell::from(format!("{}{stale}", cell(c.position, 3))).style(value_style),
            Cell::from(cell(c.speed, 2)).style(value_style),
            Cell::from(cell(c.effort, 0)).style(value_style),
            Cell::from(en).style(value_style),
            Cell::from(c.error.clone()).style(err_style),
            Cell::from(loss),
        ])
    });
    let header = Row::new(vec![
        if d.named_joints { "joint" } else { "id" }.to_owned(),
        "position deg".to_owned(),
        format!("speed {}", d.speed_unit),
        d.effort_name.to_owned(),
        "enabled".to_owned(),
        "errors".to_owned(),
        "failed".to_owned(),
    ])
    .style(Style::default().bold());
    f.render_widget(
        Table::new(
            body,
            [
                Constraint::Length(name_width),
                Constraint::Length(13),
                Constraint::Length(12),
                Constraint::Length(11),
                Constraint::Length(8),
                Constraint::Min(12),
                Constraint::Length(11),
            ],
        )
        .header(header)
        .block(Block::bordered().title(" live values ")),
        table,
    );

    let points: Vec<Vec<(f64, f64)>> = d
        .channels
        .iter()
        .map(|c| c.history.iter().copied().collect())
        .collect();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, v) in points.iter().flatten() {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    if !lo.is_finite() || hi - lo < 1.0 {
        let mid = if lo.is_finite() {
            f64::midpoint(lo, hi)
        } else {
            0.0
        };
        lo = mid - 1.0;
        hi = mid + 1.0;
    }
    let x1 = d.t.max(WINDOW_S);
    let x0 = x1 - WINDOW_S;
    let datasets = d
        .channels
        .iter()
        .zip(&points)
        .enumerate()
        .map(|(i, (c, p))| {
            Dataset::default()
                .name(c.name.clone())
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::default().fg(COLORS[i % COLORS.len()]))
                .data(p)
        })
        .collect();
    f.render_widget(
        Chart::new(datasets)
            .block(Block::bordered().title(" position, degrees (last 10 s) "))
            .x_axis(
                Axis::default()
                    .bounds([x0, x1])
                    .labels([format!("{x0:.0} s"), format!("{x1:.0} s")]),
            )
            .y_axis(
                Axis::default()
                    .bounds([lo, hi])
                    .labels([format!("{lo:.1}"), format!("{hi:.1}")]),
            ),
        plot,
    );
    let rec = d
        .recording
        .as_deref()
        .map_or_else(String::new, |r| format!("   recording to {r}"));
    f.render_widget(
        Paragraph::new(format!("q / Esc / Ctrl-C: quit{rec}")).dim(),
        foot,
    );
}
