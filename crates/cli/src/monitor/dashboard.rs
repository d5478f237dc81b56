//! The dashboard: each watched device's latest values and history, and how a frame is drawn.

use std::collections::VecDeque;
use std::fmt::Write as _;

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Style, Stylize as _};
use ratatui::symbols::Marker;
use ratatui::text::Line;
use ratatui::widgets::{Axis, Block, Cell, Chart, Dataset, GraphType, Paragraph, Row, Table};

use robobus::record::SampleTable;

use super::WINDOW_S;

/// What the dashboard shows: the library's sample table, and each row's history.
#[derive(Debug, Clone)]
pub(crate) struct Dashboard {
    /// Top line: the source.
    pub(crate) title: String,
    /// Effort column header (`current mA` / `load`).
    pub(crate) effort_name: &'static str,
    /// The devices' rows and the latest sample.
    pub(crate) table: SampleTable,
    /// (time, position) of each row, for the plot.
    pub(crate) history: Vec<VecDeque<(f64, f64)>>,
    /// Where samples are recorded.
    pub(crate) recording: Option<String>,
    /// Channels are a robot file's joints (named), not device IDs.
    pub(crate) named_joints: bool,
}

impl Dashboard {
    /// A dashboard of `table`'s rows, with no history yet.
    pub(crate) fn new(title: String, effort_name: &'static str, table: SampleTable) -> Self {
        Self {
            title,
            effort_name,
            history: vec![VecDeque::new(); table.rows.len()],
            table,
            recording: None,
            named_joints: false,
        }
    }

    pub(super) fn push_history(&mut self) {
        let t = self.table.t_s;
        for (r, h) in self.table.rows.iter().zip(&mut self.history) {
            if let Some(p) = r.position_deg {
                h.push_back((t, p));
            }
            while h.front().is_some_and(|(t0, _)| *t0 < t - WINDOW_S) {
                h.pop_front();
            }
        }
    }

    pub(super) fn plain_line(&self) -> String {
        let mut s = format!("t={:6.2}s", self.table.t_s);
        for r in &self.table.rows {
            match r.now(r.position_deg) {
                Some(p) => {
                    let _ = write!(s, "  {} {p:8.3}", r.name);
                }
                None => {
                    let _ = write!(s, "  {} {:>8}", r.name, r.error);
                }
            }
        }
        s
    }
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
    let t = &d.table;
    let rows = u16::try_from(t.rows.len()).unwrap_or(30);
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
            format!("   t = {:.1} s, {} samples", t.t_s, t.samples).into(),
            if t.lost > 0 {
                format!(", {} not shown (the terminal fell behind)", t.lost).yellow()
            } else {
                "".into()
            },
        ])),
        head,
    );
    let cell =
        |v: Option<f64>, prec: usize| v.map_or_else(|| "-".into(), |v| format!("{v:.prec$}"));
    let name_width = t
        .rows
        .iter()
        .map(|c| c.name.chars().count())
        .max()
        .unwrap_or(0)
        .clamp(4, 24);
    let name_width = u16::try_from(name_width + 1).unwrap_or(25);
    let body = t.rows.iter().map(|c| {
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
        let loss = if t.samples > 0 {
            format!(
                "{} ({:.0}%)",
                c.failures,
                100.0 * c.failures as f64 / t.samples as f64
            )
        } else {
            c.failures.to_string()
        };
        Row::new(vec![
            Cell::from(c.name.clone()),
            Cell::from(format!("{}{stale}", cell(c.position_deg, 3))).style(value_style),
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
        format!("speed {}", t.speed_unit.as_str()),
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
        .history
        .iter()
        .map(|h| h.iter().copied().collect())
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
    let x1 = t.t_s.max(WINDOW_S);
    let x0 = x1 - WINDOW_S;
    let datasets = t
        .rows
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
