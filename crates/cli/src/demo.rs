//! `robobus demo`: the built-in simulated robot ([`robobus::demo`]), rendered.
//!
//! The library runs it (a 16-servo wCK humanoid and a 7-joint WHJ arm, simulated in this
//! process and driven through the client library); this module shows its progress (bars on
//! a terminal, plain lines otherwise), writes `--plot`, and prints the report: a text
//! summary or, with `--json`, the report itself.

use std::fmt::Write as _;
use std::io::IsTerminal as _;
use std::path::PathBuf;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use robobus::demo::{AMPLITUDE_DEG, DemoConfig, DemoReport, FREQUENCY_HZ, PERIOD, Trace};
use robobus::ops::{Control, Progress};
use robobus::robot::simulated::SERVOS;
use robobus_wck::BaudRate;

use crate::Global;
use crate::exit::usage;
use crate::plot::Recording;

/// Options of `robobus demo`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// How long the WHJ arm follows its sine trajectory, seconds (0.5..=60).
    #[arg(long, default_value_t = 4.0, value_parser = parse_seconds)]
    seconds: f64,
    /// Also plot the run (wCK servo angles and WHJ joint angles over time, a panel each,
    /// their targets dashed) to this file; the format follows the extension: .png or .svg.
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() && robobus::demo::SECONDS_RANGE.contains(&v) {
        Ok(v)
    } else {
        Err(format!("--seconds {s} is out of range 0.5..=60"))
    }
}

/// Shows the library's progress: one indicatif bar per stage on a terminal, plain lines
/// on stderr otherwise.
struct Shown {
    fancy: bool,
    stage: &'static str,
    bar: ProgressBar,
}

impl Shown {
    fn new() -> Self {
        Self {
            fancy: std::io::stderr().is_terminal(),
            stage: "",
            bar: ProgressBar::hidden(),
        }
    }

    fn show(&mut self, p: &Progress) {
        let Some(total) = p.total else {
            // A note: what happens next.
            self.bar.finish_and_clear();
            self.stage = "";
            if !self.fancy
                && let Some(n) = &p.note
            {
                eprintln!("demo: {n}");
            }
            return;
        };
        if self.stage != p.stage {
            self.bar.finish_and_clear();
            self.stage = p.stage;
            self.bar = if self.fancy {
                let pb = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
                if let Ok(style) =
                    ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} {msg}")
                {
                    pb.set_style(style.progress_chars("=> "));
                }
                pb.set_prefix(p.stage);
                pb
            } else {
                eprintln!("demo: {}", p.stage);
                ProgressBar::hidden()
            };
        }
        self.bar.set_position(p.done);
        if let Some(n) = &p.note {
            self.bar.set_message(n.clone());
            if !self.fancy && p.stage == "keyframes" {
                eprintln!("demo: {n}");
            }
        }
    }
}

/// Runs `robobus demo`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    if let Some(p) = &args.plot {
        let ext = p
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("png" | "svg")) {
            return Err(usage(format!(
                "--plot {}: the file name must end in .png or .svg",
                p.display()
            )));
        }
        crate::output::check_output_path(p, "--plot")?;
    }
    if g.dry_run {
        return Err(usage(
            "robobus demo: --dry-run has nothing to print (the demo talks to its own \
             in-process simulators)",
        ));
    }
    let stop = crate::interrupt::stop_token();
    let mut shown = Shown::new();
    let mut on_progress = |p: &Progress| shown.show(p);
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let result = robobus::demo::run(
        &DemoConfig {
            seconds: args.seconds,
        },
        &mut control,
    );
    drop(control);
    shown.bar.finish_and_clear();
    let mut report = result?;
    if let Some(path) = &args.plot {
        crate::plot::write_image(
            &recording(&report.trace),
            path,
            "robobus demo: simulated robot",
        )?;
        if !shown.fancy {
            eprintln!("demo: wrote {}", path.display());
        }
        report.plot = Some(path.display().to_string());
    }
    if g.json {
        crate::output::print_json(&serde_json::to_value(&report)?)
    } else {
        crate::output::print(&summary_text(&report, args.plot.as_ref()))
    }
}

/// The trace as a recording for the plot: the traced angles and their targets
/// (`wck0_deg` and `wck0_target_deg`, ...), which the plot pairs.
fn recording(trace: &Trace) -> Recording {
    let (time, signals) = trace.rows();
    Recording {
        time_name: "t_s".into(),
        time,
        signals: Trace::names().into_iter().zip(signals).collect(),
    }
}

fn us(d: core::time::Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

#[allow(clippy::too_many_lines)] // one line of output per statement
fn summary_text(r: &DemoReport, plot: Option<&PathBuf>) -> String {
    let (w, h) = (&r.wck, &r.whj);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "wCK humanoid: {SERVOS} x wCK-1108 on one 115200 bit/s bus (simulated, in-process)"
    );
    let _ = writeln!(
        s,
        "  scan    IDs 0..=30 in {:.0} ms: found {} servos ({}..={})",
        w.scan_ms,
        w.servos_found,
        w.ids.first().copied().unwrap_or(0),
        w.ids.last().copied().unwrap_or(0)
    );
    for p in &w.poses {
        match p.settled_ms {
            Some(ms) => {
                let _ = writeln!(
                    s,
                    "  pose    {:<8} played {ms:>4.0} ms (transition and hold): all {SERVOS} \
                     servos within 1 step (1.06 deg)",
                    p.name
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "  pose    {:<8} still {} steps off at the end of its play",
                    p.name, p.worst_error_steps
                );
            }
        }
    }
    let _ = writeln!(
        s,
        "  bus     {} status polls, {} transactions, {} retries, {} timeouts; {} bytes out, \
         {} back; wire busy {:.1} % (the wire allows {:.0} polls of all {SERVOS} servos per s)",
        w.status_polls,
        w.transactions,
        w.retries,
        w.timeouts,
        w.bytes_out,
        w.bytes_in,
        100.0 * w.wire_utilisation,
        robobus_wck::timing::polling_rate_hz(usize::from(SERVOS), BaudRate::B115200)
    );
    let _ = writeln!(s);
    let model = h.identities.first().map_or("?", |t| t.model.as_str());
    let _ = writeln!(
        s,
        "WHJ arm: {} x {model} on one CAN FD bus (1 Mbit/s arbitration, 5 Mbit/s data; simulated, in-process)",
        h.joints
    );
    let fw = h.identities.first().map_or("?", |t| t.firmware.as_str());
    let _ = writeln!(
        s,
        "  start   IAP release, identify (firmware {fw}), position mode, enable"
    );
    let st = &h.stats;
    let _ = writeln!(
        s,
        "  sine    {:.1} s, {AMPLITUDE_DEG} deg at {FREQUENCY_HZ} Hz: {} cycles at 500 Hz, {} complete, \
         {} deadline misses, {} missing replies, {} overruns",
        h.seconds, st.cycles, st.complete, st.deadline_misses, st.missing_replies, st.overruns
    );
    for t in &h.tracking {
        let _ = writeln!(
            s,
            "          joint {}: tracking error rms {:.3} deg, max {:.3} deg; error bits: {}",
            t.joint, t.rms_deg, t.max_deg, t.error
        );
    }
    let rt = st.round_trip;
    let _ = writeln!(
        s,
        "  latency round trip p50 {:.0} us, p90 {:.0} us, p99 {:.0} us, max {:.0} us; \
         cycle start late p99 {:.0} us",
        us(rt.p50),
        us(rt.p90),
        us(rt.p99),
        us(rt.max),
        us(st.start_lateness.p99)
    );
    let _ = writeln!(
        s,
        "  bus     {} frames per cycle take {:.0} us on the wire: {:.1} % busy at 500 Hz \
         (the wire allows about {:.0} Hz)",
        2 * h.joints,
        us(h.cycle_wire),
        100.0 * h.cycle_wire.as_secs_f64() / PERIOD.as_secs_f64(),
        1.0 / h.cycle_wire.as_secs_f64().max(1e-9)
    );
    let _ = writeln!(s);
    if let Some(p) = plot {
        let _ = writeln!(s, "plot written to {}", p.display());
    }
    let _ = writeln!(
        s,
        "done in {:.1} s. Next: `robobus sim wck` / `robobus sim whj` serve these simulators \
         to other programs; `robobus monitor --sim` watches one live.",
        r.wall_s
    );
    s
}
