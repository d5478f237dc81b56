//! The report's studio section: the studio's server, its telemetry streams and its
//! WebSocket under load.

use std::fmt::Write as _;

use super::pct;
use crate::codec::us;
use crate::stats::Summary;
use crate::{Results, studio};

/// The report's studio section alone, with the machine it ran on.
pub fn studio_markdown(r: &Results) -> String {
    let mut o = String::new();
    studio_section(&mut o, r);
    let m = &r.machine;
    let _ = writeln!(
        o,
        "Machine: {} logical CPUs, {}, Linux {}; load average before: {}; after: {}.",
        m.cpus, m.model, m.kernel, m.load_before, m.load_after
    );
    o
}

pub(super) fn ms(us: f64) -> String {
    format!("{:.2}", us / 1e3)
}

#[allow(clippy::too_many_lines)] // one section, table by table
pub(super) fn studio_section(o: &mut String, r: &Results) {
    let _ = writeln!(o, "## Studio\n");
    let Some(st) = &r.studio else {
        let _ = writeln!(o, "Not run.\n");
        return;
    };
    let m = &st.model;
    let period = us(studio::BUS_PERIOD);
    let _ = writeln!(
        o,
        "`robobus-studio` serving the built-in simulated robot on the wall clock \
         (`Station::simulated_live`: 7 WHJ30 joints on `sim-whj`, in-process memory bus, \
         1 / 5 Mbit/s wire, 20 µs processing delay; 16 wCK servos on `sim-wck`) on a thread \
         of this process, and its pages played by WebSocket clients (`tungstenite`, \
         TCP_NODELAY, like a browser) on threads of this process. Each page subscribes to \
         `{{\"op\": \"whj.sample\", \"joints\": \"1-7\"}}` at {:.0} Hz with {:.0} fps; \
         every page's stream subscribes to the studio's one sampling of the bus \
         (`Station::telemetry`), so N pages cost the bus one stream's frames. Everything \
         runs on one machine: the pages, the studio and the simulators share its cores.\n",
        studio::ASKED_HZ,
        studio::FPS
    );
    let _ = writeln!(
        o,
        "Wire model (the exact frames of one sample and of one servo cycle, recorded on a \
         second simulated chain and timed with `robobus_whj::timing::frame_duration`):\n\n\
         - one `whj.sample` of 7 joints = {} request/reply transactions (a status query \
         and a speed read per joint), {:.1} µs back to back on the wire: the wire could \
         carry **{:.0} samples/s** with one stream on it;\n\
         - the client holds each reply from its caller for a second answer from a \
         duplicate node (an arbitration loser's frame of the reply's length, plus the \
         link's allowance, {:.0} µs on this memory bus); a sample's requests go out \
         together (`JointBus::request_many`), so the holds overlap the other requests' \
         frames and the wire's figure is the limit;\n\
         - one jog = one position servo frame and its feedback, {:.1} µs on the wire; a \
         7-joint position servo cycle {:.1} µs;\n\
         - **\"the bus period\" below is {:.0} µs, the period of the {:.0} Hz the pages ask \
         for**, not a wire time.\n",
        m.transactions,
        us(m.sample),
        m.wire_hz(),
        us(m.collision_window),
        us(m.jog),
        us(m.servo_cycle),
        period,
        studio::ASKED_HZ
    );
    let _ = writeln!(
        o,
        "**Telemetry fan-out.** Samples taken: by the studio's sampling of the stream, \
         from the delivered samples' `seq` and `unix_ms` (the page that saw fewest); each \
         page asks {:.0} Hz. Same sample: of the samples a later page received with a \
         `seq` the first page received too, those with the first page's read instant \
         (`unix_ms`); all of them when one sampling serves every page. Delivered: \
         `telemetry` messages a page read per second (the page that read fewest). Skipped: \
         the `skipped` totals of all pages (taken and never sent: the frame rate is below \
         the sampling rate). Age: the page's clock when it read the message − the \
         sample's `unix_ms` (when its read completed), all pages: it includes the wait in \
         the studio's forwarder, which sends the latest sample at each frame tick, up to \
         one sample period. Late: delivered samples the sampler marked `late` (its read \
         started more than a period, 2 ms, after its slot). A page can be delivered at \
         most min(fps, samples taken) a second.\n",
        studio::ASKED_HZ
    );
    let _ = writeln!(
        o,
        "| pages | samples taken/s | / asked | / wire limit | same sample | delivered msg/s per page | delivered / fps | delivered / min(fps, taken) | skipped | late / failed delivered | age p50 ms | age p99 ms |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for f in &st.fan_out {
        let taken = f.fewest_taken_hz();
        let fewest = f
            .pages
            .iter()
            .map(studio::Page::delivered_hz)
            .fold(f64::INFINITY, f64::min);
        let fewest = if fewest.is_finite() { fewest } else { 0.0 };
        let ages = f.ages();
        let (same, common) = f.same_samples();
        let same = if f.pages.len() < 2 {
            "–".to_owned()
        } else {
            format!("{same} of {common}")
        };
        let _ = writeln!(
            o,
            "| {} | {:.1} | {:.3}× | {:.3}× | {same} | {:.1} | {:.3}× | {:.3}× | {} | {} / {} | {} | {} |",
            f.subscribers,
            taken,
            taken / studio::ASKED_HZ,
            taken / m.wire_hz().max(1e-9),
            fewest,
            fewest / studio::FPS,
            fewest / studio::FPS.min(taken).max(1e-9),
            f.pages.iter().map(|p| p.skipped).sum::<u64>(),
            f.pages.iter().map(|p| p.late).sum::<u64>(),
            f.pages.iter().map(|p| p.failed).sum::<u64>(),
            ms(ages.p50),
            ms(ages.p99),
        );
    }
    let _ = writeln!(o);
    let _ = writeln!(
        o,
        "CPU over the same window, as a share of one core: the process (`getrusage`), \
         of it the pages' threads (each its own `RUSAGE_THREAD`), the simulators' serving \
         threads (`sim-whj`, `robobus-sim-wck`, from `/proc/self/task/*/stat`, 10 ms \
         ticks) and the benchmark's waiting thread; the studio = the rest (its runtime \
         thread, the stream forwarders, the samplers, the WHJ bus thread, the guard, the \
         blocking pool).\n"
    );
    let _ = writeln!(
        o,
        "| pages | process | pages' threads | simulators | studio | studio per page |\n|---|---|---|---|---|---|"
    );
    for f in &st.fan_out {
        let n = f.subscribers.max(1) as f64;
        let _ = writeln!(
            o,
            "| {} | {} | {} | {} | {} | {} |",
            f.subscribers,
            pct(f.share(f.process_cpu)),
            pct(f.share(f.clients_cpu)),
            pct(f.share(f.sims_cpu)),
            pct(f.share(f.server_cpu())),
            pct(f.share(f.server_cpu()) / n),
        );
    }
    let _ = writeln!(o);
    let j = &st.jog;
    let reply = Summary::of_us(&j.reply_us);
    let wire = Summary::of_us(&j.wire_us);
    let gap = Summary::of_us(&j.poll_gap_us);
    let _ = writeln!(
        o,
        "**Jog latency.** One controlling page (take control, arm, heartbeat every 100 ms \
         on the same socket; joint 1 put in position mode) sends `{{\"type\": \"jog\", \
         \"family\": \"whj\", \"device\": 1, \"target\": ±1}}` at {:.0} Hz for {:.1} s. \
         **Reply**: the jog message written → its `jogged` reply read by the page (the \
         studio's runtime, the jogger on the blocking pool, the position servo frame \
         out, the joint's feedback back, its duplicate check (a loser's frame plus the \
         link's {:.0} µs allowance), the reply message). **At the joint**: the jog message written → the simulated joint's \
         position target seen changed to the position sent (`LiveSimulator::snapshot`, \
         polled in a tight loop, yielding, by a thread of this process from the moment \
         the jog is sent; the simulator publishes its state after each frame it takes \
         in; the poll gap is how precisely the poll timed it). Ratios against the bus \
         period, {:.0} µs.\n",
        studio::JOG_HZ,
        j.wall.as_secs_f64(),
        us(m.collision_window),
        period
    );
    let _ = writeln!(
        o,
        "| jogs | errors / unanswered | limited | heartbeats | reply p50 ms | reply p99 ms | reply p50 / p99 ÷ bus period | at the joint p50 ms | at the joint p99 ms | at the joint p50 / p99 ÷ bus period | poll gap p50 / p99 ms | not seen at the joint |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    let _ = writeln!(
        o,
        "| {} | {} / {} | {} | {} | {} | {} | {:.2}× / {:.2}× | {} | {} | {:.2}× / {:.2}× | {} / {} | {} |",
        j.sent,
        j.errors,
        j.unanswered,
        j.limited,
        j.heartbeats,
        ms(reply.p50),
        ms(reply.p99),
        reply.p50 / period,
        reply.p99 / period,
        ms(wire.p50),
        ms(wire.p99),
        wire.p50 / period,
        wire.p99 / period,
        ms(gap.p50),
        ms(gap.p99),
        j.unmatched
    );
    let _ = writeln!(o);
}
