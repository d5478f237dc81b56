//! Latency histograms as hand-written SVG (no fonts to embed, no plotting dependency).

use std::fmt::Write as _;

use crate::stats::{Summary, percentile};

const W: f64 = 640.0;
const H: f64 = 300.0;
const LEFT: f64 = 60.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 50.0;
const BINS: usize = 60;

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A histogram of `samples_us` (microseconds) from the smallest sample to the 99.9th
/// percentile (a note gives the count beyond), with a logarithmic count axis and vertical
/// lines at `markers` (label, µs), e.g. the modelled wire time and the median.
#[allow(clippy::too_many_lines)] // one drawing, element by element
pub fn histogram(title: &str, samples_us: &[f64], markers: &[(&str, f64)]) -> String {
    let mut s: Vec<f64> = samples_us
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .collect();
    s.sort_by(f64::total_cmp);
    let sum = Summary::of_us(&s);
    let lo_data = s.first().copied().unwrap_or(0.0);
    let lo = markers.iter().map(|m| m.1).fold(lo_data, f64::min).max(0.0);
    let mut hi = percentile(&s, 0.999).max(lo + 1.0);
    for m in markers {
        if m.1 > hi && m.1 < 2.0 * hi {
            hi = m.1 * 1.02;
        }
    }
    let width = (hi - lo) / BINS as f64;
    let mut counts = [0u64; BINS];
    let mut beyond = 0u64;
    for &x in &s {
        if x > hi {
            beyond += 1;
            continue;
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // clamped
        let i = (((x - lo) / width) as usize).min(BINS - 1);
        if let Some(c) = counts.get_mut(i) {
            *c += 1;
        }
    }
    let top = counts.iter().copied().max().unwrap_or(1).max(1) as f64;
    let plot_w = W - LEFT - RIGHT;
    let plot_h = H - TOP - BOTTOM;
    let y_of = |c: u64| -> f64 {
        if c == 0 {
            0.0
        } else {
            plot_h * (1.0 + c as f64).log10() / (1.0 + top).log10()
        }
    };
    let x_of = |v: f64| LEFT + plot_w * (v - lo) / (hi - lo);
    let mut o = String::new();
    let _ = writeln!(
        o,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif" font-size="11">"#
    );
    let _ = writeln!(o, r#"<rect width="{W}" height="{H}" fill="white"/>"#);
    let _ = writeln!(
        o,
        r#"<text x="{}" y="18" text-anchor="middle" font-size="13">{}</text>"#,
        W / 2.0,
        esc(title)
    );
    let _ = writeln!(
        o,
        r##"<text x="{}" y="32" text-anchor="middle" fill="#555">n = {}, p50 {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs{}</text>"##,
        W / 2.0,
        sum.n,
        sum.p50,
        sum.p99,
        sum.p999,
        sum.max,
        if beyond > 0 {
            format!(" ({beyond} beyond the axis)")
        } else {
            String::new()
        }
    );
    for (i, &c) in counts.iter().enumerate() {
        let h = y_of(c);
        if h <= 0.0 {
            continue;
        }
        let x = LEFT + plot_w * i as f64 / BINS as f64;
        let _ = writeln!(
            o,
            r##"<rect x="{x:.1}" y="{:.1}" width="{:.1}" height="{h:.1}" fill="#4a7bd0"/>"##,
            TOP + plot_h - h,
            (plot_w / BINS as f64 - 1.0).max(0.5)
        );
    }
    // Axes and ticks.
    let _ = writeln!(
        o,
        r#"<path d="M{LEFT} {TOP} V{} H{}" stroke="black" fill="none"/>"#,
        TOP + plot_h,
        LEFT + plot_w
    );
    for k in 0..=5 {
        let v = lo + (hi - lo) * f64::from(k) / 5.0;
        let x = x_of(v);
        let _ = writeln!(
            o,
            r#"<line x1="{x:.1}" y1="{}" x2="{x:.1}" y2="{}" stroke="black"/><text x="{x:.1}" y="{}" text-anchor="middle">{v:.0}</text>"#,
            TOP + plot_h,
            TOP + plot_h + 4.0,
            TOP + plot_h + 16.0
        );
    }
    let _ = writeln!(
        o,
        r#"<text x="{}" y="{}" text-anchor="middle">latency, µs</text>"#,
        LEFT + plot_w / 2.0,
        H - 12.0
    );
    let _ = writeln!(
        o,
        r#"<text x="14" y="{}" text-anchor="middle" transform="rotate(-90 14 {})">count (log scale, max {top:.0})</text>"#,
        TOP + plot_h / 2.0,
        TOP + plot_h / 2.0
    );
    let colors = ["#d03030", "#208020", "#a040a0", "#c08000"];
    for (i, (label, v)) in markers.iter().enumerate() {
        if *v < lo || *v > hi {
            continue;
        }
        let x = x_of(*v);
        let c = colors.get(i % colors.len()).copied().unwrap_or("black");
        let _ = writeln!(
            o,
            r#"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{}" stroke="{c}" stroke-dasharray="4 3"/><text x="{:.1}" y="{}" fill="{c}">{}</text>"#,
            TOP + plot_h,
            x + 3.0,
            TOP + 12.0 + 12.0 * i as f64,
            esc(label)
        );
    }
    o.push_str("</svg>\n");
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_is_well_formed_svg_with_markers() {
        let samples: Vec<f64> = (0..1000).map(|i| 100.0 + f64::from(i % 50)).collect();
        let svg = histogram("a <b> & c", &samples, &[("model 90 µs", 90.0)]);
        assert!(svg.starts_with("<svg"));
        assert!(svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("a &lt;b&gt; &amp; c"));
        assert!(svg.contains("model 90 µs"));
        assert!(svg.matches("<rect").count() > 10);
    }
}
