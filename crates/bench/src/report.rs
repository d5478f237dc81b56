//! The Markdown report with its SVG plots.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use robobus::whj::Protocol;

use crate::codec::{describe, us};
use crate::stats::Summary;
use crate::{BenchError, Results, studio, svg, telemetry, wck};

/// Control-loop goal: this share of the modelled physical limit.
pub const LOOP_GOAL: f64 = 0.97;
/// Telemetry goal: this share of the rate asked, or of what the wire allows for one sample
/// where that is lower.
pub const TELEMETRY_WIRE_GOAL: f64 = 0.9;
/// Peer goal: ours at least this many times the Python peer's cycle rate.
pub const PEER_GOAL: f64 = 5.0;
/// Telemetry goal: with eight subscribers (one idle) the stream keeps this share of its
/// rate with one.
pub const TELEMETRY_GOAL: f64 = 0.98;
/// Codec goal, ns per packet.
pub const CODEC_GOAL_NS: f64 = 50.0;

fn pct(x: f64) -> String {
    format!("{:.1} %", 100.0 * x)
}

fn mark(ok: bool) -> &'static str {
    if ok { "yes" } else { "**no**" }
}

fn baud_name(bps: u32) -> String {
    format!("{bps}")
}

/// Writes `report.md` and the plots into `dir`; returns the report's path.
pub fn write(results: &Results, dir: &Path) -> Result<PathBuf, BenchError> {
    std::fs::create_dir_all(dir)
        .map_err(|e| BenchError::new(format!("creating {}", dir.display()), e))?;
    let mut plots: Vec<(String, String)> = Vec::new();
    let md = render(results, &mut plots);
    for (name, svg) in &plots {
        let p = dir.join(name);
        std::fs::write(&p, svg)
            .map_err(|e| BenchError::new(format!("writing {}", p.display()), e))?;
    }
    let path = dir.join("report.md");
    std::fs::write(&path, md)
        .map_err(|e| BenchError::new(format!("writing {}", path.display()), e))?;
    Ok(path)
}

/// The loops checked against the 97 % goal: (name, efficiency).
pub fn loop_efficiencies(r: &Results) -> Vec<(String, f64)> {
    let mut v = Vec::new();
    for p in &r.polls {
        v.push((format!("wCK polling {}", p.spec.label()), p.efficiency()));
    }
    for s in &r.streams {
        v.push((
            format!(
                "wCK sync-move streaming, {} bit/s",
                s.baud.bits_per_second()
            ),
            s.efficiency(),
        ));
    }
    for f in &r.free {
        v.push((
            format!("WHJ free-running, {} ({})", f.spec.label(), f.link),
            f.efficiency(),
        ));
    }
    for f in r.fixed.iter().filter(|f| f.feasible()) {
        v.push((
            format!(
                "WHJ {} Hz {} joints {}, wait {} (median round trip)",
                f.hz,
                f.spec.joints,
                proto(f.protocol),
                f.spec.wait
            ),
            f.efficiency(),
        ));
    }
    v
}

fn proto(p: Protocol) -> &'static str {
    match p {
        Protocol::PointToPoint => "point-to-point",
        Protocol::Broadcast => "broadcast",
    }
}

/// Peer comparisons: (name, ours/theirs rate, theirs/ours CPU per cycle).
pub fn peer_ratios(r: &Results) -> Vec<(String, f64, f64)> {
    let mut v = Vec::new();
    for p in &r.polls {
        if let Some(peer) = &p.peer {
            v.push((
                format!(
                    "wCK polling {} servos, {} bit/s, zero turnaround, wait {}, guard {} (pyserial)",
                    p.spec.servos,
                    p.spec.baud.bits_per_second(),
                    p.spec.wait,
                    if p.spec.guard { "default" } else { "off" }
                ),
                p.rate_hz() / peer.rate_hz().max(1e-9),
                peer.cpu_per_cycle_us() / p.cpu_per_cycle_us().max(1e-9),
            ));
        }
    }
    for f in &r.udp {
        if let Some(peer) = &f.peer {
            v.push((
                format!(
                    "WHJ servo cycle {}, UDP, {} (python-can)",
                    f.spec.label(),
                    if f.spec.fast_wire {
                        "wire off"
                    } else {
                        "1 / 5 Mbit/s wire"
                    }
                ),
                f.rate_hz() / peer.rate_hz().max(1e-9),
                peer.cpu_per_cycle_us() / f.cpu_per_cycle_us().max(1e-9),
            ));
        }
    }
    v
}

/// Each telemetry run with eight subscribers against the run at the same rate with one:
/// (rate, rate with 8 / rate with 1).
pub fn telemetry_ratios(r: &Results) -> Vec<(f64, f64)> {
    r.telemetry
        .iter()
        .filter(|t| t.subscribers > 1)
        .filter_map(|many| {
            let one = r
                .telemetry
                .iter()
                .find(|t| t.subscribers == 1 && t.rate_hz.total_cmp(&many.rate_hz).is_eq())?;
            Some((many.rate_hz, many.rate() / one.rate().max(1e-9)))
        })
        .collect()
}

/// The report's telemetry section alone.
pub fn telemetry_markdown(r: &Results) -> String {
    let mut o = String::new();
    telemetry_section(&mut o, r);
    o
}

fn telemetry_section(o: &mut String, r: &Results) {
    let _ = writeln!(o, "## Telemetry\n");
    let _ = writeln!(
        o,
        "`Station::telemetry` (the station's one sampling of a bus, shared by its \
         subscribers) streaming `whj.sample` of the live simulated arm's 7 joints (1 / 5 \
         Mbit/s wire, wall clock; two frames per joint per sample), each subscriber with a \
         queue of {} samples. With eight subscribers, seven read on their own threads and \
         one never reads. *Reachable*: the rate asked, or what the wire allows for one \
         sample (its exact frames back to back) where that is lower.\n",
        telemetry::QUEUE
    );
    let _ = writeln!(
        o,
        "| requested | subscribers | sampled by | samples/s | wire allows | of reachable | late | lost by readers | fewest received | idle queue / lost |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    for t in &r.telemetry {
        let idle = if t.subscribers > 1 {
            format!("{} / {}", t.idle_queued, t.idle_lost)
        } else {
            "–".into()
        };
        let _ = writeln!(
            o,
            "| {:.0} Hz | {} | {} | {:.1} | {:.0} /s | {:.3}× | {} | {} | {} | {idle} |",
            t.rate_hz,
            t.subscribers,
            t.sampled_by,
            t.rate(),
            t.wire_hz,
            t.of_reachable(),
            t.late,
            t.lost_by_readers,
            t.min_received,
        );
    }
    let _ = writeln!(o);
    for (hz, ratio) in telemetry_ratios(r) {
        let _ = writeln!(
            o,
            "- At {hz:.0} Hz, the rate with eight subscribers is {ratio:.3}× the rate with one."
        );
    }
    let _ = writeln!(o);
}

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

fn ms(us: f64) -> String {
    format!("{:.2}", us / 1e3)
}

#[allow(clippy::too_many_lines)] // one section, table by table
fn studio_section(o: &mut String, r: &Results) {
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
         the studio starts one sampler per page's stream, so N pages share the one bus. \
         Everything runs on one machine: the pages, the studio and the simulators share \
         its cores.\n",
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
         - the client credits each reply after its {:.0} µs collision window \
         (`JointBusConfig::collision_window`), so the library's own limit, all other costs \
         zero, is **{:.0} samples/s** for one stream (its requests go one after the \
         other; streams of several pages overlap their windows on different joints, so \
         together they can exceed it);\n\
         - one jog = one position servo frame and its feedback, {:.1} µs on the wire; a \
         7-joint position servo cycle {:.1} µs;\n\
         - **\"the bus period\" below is {:.0} µs, the period of the {:.0} Hz the pages ask \
         for**, not a wire time.\n",
        m.transactions,
        us(m.sample),
        m.wire_hz(),
        us(m.collision_window),
        m.windowed_hz(),
        us(m.jog),
        us(m.servo_cycle),
        period,
        studio::ASKED_HZ
    );
    let _ = writeln!(
        o,
        "**Telemetry fan-out.** Samples taken: by the studio's samplers, from the delivered \
         samples' `seq` and `unix_ms` (all streams together; per stream in brackets); \
         each page asks {:.0} Hz for its own stream, and all streams share the one \
         bus, so the wire limit is compared with all of them together. Delivered: `telemetry` messages a page read per second (the page that read \
         fewest). Skipped: the `skipped` totals of all pages (taken and never sent: the \
         frame rate is below the sampling rate). Age: the page's clock when it read the \
         message − the sample's `unix_ms` (when its read completed), all pages: it \
         includes the wait in the studio's forwarder, which sends the latest sample at \
         each frame tick, up to one sample period. Late: delivered samples the sampler \
         marked `late` (its read started more than a period, 2 ms, after its slot). A \
         page can be delivered at most min(fps, its stream's samples taken) a second.\n",
        studio::ASKED_HZ
    );
    let _ = writeln!(
        o,
        "| pages | samples taken/s, all streams (per stream) | per stream / asked | all / wire limit | per stream / windowed limit | delivered msg/s per page | delivered / fps | delivered / min(fps, taken) | skipped | late / failed delivered | age p50 ms | age p99 ms |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for f in &st.fan_out {
        let n = f.subscribers.max(1) as f64;
        let taken = f.taken_hz();
        let fewest = f
            .pages
            .iter()
            .map(studio::Page::delivered_hz)
            .fold(f64::INFINITY, f64::min);
        let fewest = if fewest.is_finite() { fewest } else { 0.0 };
        let ages = f.ages();
        let _ = writeln!(
            o,
            "| {} | {:.1} ({:.1}) | {:.3}× | {:.3}× | {:.3}× | {:.1} | {:.3}× | {:.3}× | {} | {} / {} | {} | {} |",
            f.subscribers,
            taken,
            taken / n,
            taken / n / studio::ASKED_HZ,
            taken / m.wire_hz().max(1e-9),
            taken / n / m.windowed_hz().max(1e-9),
            fewest,
            fewest / studio::FPS,
            fewest / studio::FPS.min(taken / n).max(1e-9),
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
         out, the joint's feedback back, the {:.0} µs collision window, the reply \
         message). **At the joint**: the jog message written → the simulated joint's \
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

#[allow(clippy::too_many_lines, clippy::many_single_char_names)] // one report, section by section
fn render(r: &Results, plots: &mut Vec<(String, String)>) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "# robobus benchmark report\n");
    if r.smoke {
        let _ = writeln!(
            o,
            "**Smoke mode**: every benchmark ran briefly to check that it runs; the numbers \
             are not meaningful.\n"
        );
    }

    // Summary.
    let _ = writeln!(o, "## Summary\n");
    let loops = loop_efficiencies(r);
    let met = loops.iter().filter(|l| l.1 >= LOOP_GOAL).count();
    let _ = writeln!(o, "| goal | result | met |\n|---|---|---|");
    if let Some(worst) = loops.iter().min_by(|a, b| a.1.total_cmp(&b.1)) {
        let _ = writeln!(
            o,
            "| control loops ≥ {} of the modelled limit | {met} of {} loops; lowest {} ({}) | {} |",
            pct(LOOP_GOAL),
            loops.len(),
            pct(worst.1),
            worst.0,
            mark(met == loops.len())
        );
    }
    for (name, rate, cpu) in peer_ratios(r) {
        let _ = writeln!(
            o,
            "| ours ≥ {PEER_GOAL}× the peer's cycle rate: {name} | {rate:.2}× the rate, {cpu:.1}× less CPU per cycle | {} |",
            mark(rate >= PEER_GOAL)
        );
    }
    for c in &r.codec {
        let _ = writeln!(
            o,
            "| codec < {CODEC_GOAL_NS} ns per packet: {} | {:.1} ns | {} |",
            c.name,
            c.ns_per_packet(),
            mark(c.ns_per_packet() < CODEC_GOAL_NS)
        );
    }
    for (hz, ratio) in telemetry_ratios(r) {
        let _ = writeln!(
            o,
            "| telemetry keeps its rate with 8 subscribers (one idle): {hz:.0} Hz | {ratio:.3}× the rate with one | {} |",
            mark(ratio >= TELEMETRY_GOAL)
        );
    }
    for t in &r.telemetry {
        let _ = writeln!(
            o,
            "| telemetry ≥ {TELEMETRY_WIRE_GOAL}× of the rate asked or the wire's for one sample: {:.0} Hz, {} subscriber(s) | {:.3}× of {:.0} /s | {} |",
            t.rate_hz,
            t.subscribers,
            t.of_reachable(),
            t.reachable_hz(),
            mark(t.of_reachable() >= TELEMETRY_WIRE_GOAL)
        );
    }
    let _ = writeln!(o);
    if r.failures > 0 || !r.notes.is_empty() {
        let _ = writeln!(o, "Notes:\n");
        for n in &r.notes {
            let _ = writeln!(o, "- {n}");
        }
        let _ = writeln!(o);
    }

    // Machine.
    let m = &r.machine;
    let _ = writeln!(o, "## Machine\n");
    let _ = writeln!(
        o,
        "- {} logical CPUs, {}\n- Linux {}\n- load average before: {}; after: {}\n",
        m.cpus, m.model, m.kernel, m.load_before, m.load_after
    );

    // Codec.
    let _ = writeln!(o, "## Codec\n");
    let _ = writeln!(
        o,
        "Per iteration: everything the client and the device side do with one packet \
         (wCK: encode, device-side stream decode, reply decode) or frame (WHJ: encode and \
         decode). ns per packet counts the command and its reply as two packets.\n"
    );
    let _ = writeln!(
        o,
        "| case | what | ns per iteration (loop) | criterion mean, ns | ns per packet |\n|---|---|---|---|---|"
    );
    for c in &r.codec {
        let _ = writeln!(
            o,
            "| {} | {} | {:.1} | {} | {:.1} |",
            c.name,
            describe(c.name),
            c.ns_per_iter,
            c.criterion_ns
                .map_or_else(|| "–".into(), |x| format!("{x:.1}")),
            c.ns_per_packet()
        );
    }
    let _ = writeln!(o);

    // wCK polling.
    let _ = writeln!(o, "## wCK polling\n");
    let _ = writeln!(
        o,
        "Client: `robobus::wck::WckBus` + `Servo::status` on the pty of the simulator's \
         endpoint (wall clock; each reply byte released when its stop bit would leave the \
         wire). Modelled cycle: N × (60 / baud + turnaround). Efficiency uses the mean cycle \
         (the cycle rate); \"at median cycle\" uses the median, which a few preempted cycles \
         on a busy machine do not move. Overhead = (measured mean − modelled) per \
         transaction. Wait: how the client waits for each reply (`WckConfig::wait`: sleep \
         in the kernel, or spin from 100 µs before the reply is due); in the spin rows the \
         endpoint serves in its precise mode (it polls for requests and spins to each \
         release instant). Link: the pty, or an in-process memory byte link to the same \
         endpoint (no kernel between client and simulator). Simulator late: how late the \
         endpoint released the reply bytes against their modelled instants (p50 / p99). \
         Guard: the client's quiet time after each reply (`WckConfig::guard`), its default \
         (one byte time plus the modules' 3 µs turnaround spread: 89.8 µs at 115200 bit/s, \
         13.9 µs at 921600) or off (`Some(0)`), each case run both ways one after the \
         other; default / off = the default's cycle rate over the same case's with the \
         guard off. The simulated modules answer alone, so the guard never fires here: \
         the ratio is what its quiet time costs.\n"
    );
    let _ = writeln!(
        o,
        "| servos | baud | turnaround | wait | link | guard | default / off | modelled cycle µs | measured mean µs | p99 µs | cycles/s | efficiency | at median cycle | overhead µs/transaction | errors | client CPU µs/cycle | endpoint CPU % | simulator late p50 / p99 |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for p in &r.polls {
        let s = Summary::of_us(&p.cycle_us);
        // The same case with the guard off, for the ratio on the default's row.
        let off = r.polls.iter().find(|q| {
            p.spec.guard
                && q.spec
                    == wck::PollSpec {
                        guard: false,
                        ..p.spec
                    }
        });
        let ratio = off.map_or_else(String::new, |q| {
            format!("{:.2}×", p.rate_hz() / q.rate_hz().max(1e-9))
        });
        let _ = writeln!(
            o,
            "| {} | {} | {} | {} | {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {} | {} | {:.1} | {} | {:.1} | {:.1} | {} / {} |",
            p.spec.servos,
            baud_name(p.spec.baud.bits_per_second()),
            if p.spec.manual_turnaround {
                "manual"
            } else {
                "zero"
            },
            p.spec.wait,
            if p.spec.memory { "memory" } else { "pty" },
            if p.spec.guard { "default" } else { "off" },
            ratio,
            us(p.spec.modelled_cycle()),
            1e6 / p.rate_hz().max(1e-9),
            s.p99,
            p.rate_hz(),
            pct(p.efficiency()),
            pct(us(p.spec.modelled_cycle()) / s.p50.max(1e-9)),
            (1e6 / p.rate_hz().max(1e-9) - us(p.spec.modelled_cycle()))
                / f64::from(p.spec.servos.max(1)),
            p.errors,
            p.cpu_per_cycle_us(),
            100.0 * p.endpoint.cpu.as_secs_f64() / p.endpoint.wall.as_secs_f64().max(1e-9),
            opt_us(p.endpoint.lateness.p50),
            opt_us(p.endpoint.lateness.p99)
        );
        if p.spec.servos == 31 || r.smoke {
            let name = format!(
                "wck_poll_{}_{}_{}_{}_{}_{}.svg",
                p.spec.servos,
                p.spec.baud.bits_per_second(),
                if p.spec.manual_turnaround {
                    "manual"
                } else {
                    "zero"
                },
                if p.spec.wait.spins() { "spin" } else { "sleep" },
                if p.spec.memory { "memory" } else { "pty" },
                if p.spec.guard { "guard" } else { "noguard" }
            );
            plots.push((
                name,
                svg::histogram(
                    &format!("wCK polling cycle, {}", p.spec.label()),
                    &p.cycle_us,
                    &[("model", us(p.spec.modelled_cycle()))],
                ),
            ));
        }
    }
    let _ = writeln!(o);
    for (name, _) in plots.iter().filter(|p| p.0.starts_with("wck_poll")) {
        let _ = writeln!(o, "![{name}]({name})");
    }
    let _ = writeln!(o);

    // Streaming.
    let _ = writeln!(o, "## wCK synchronized-move streaming\n");
    let _ = writeln!(
        o,
        "`WckBus::sync_move` to 31 servos, paced at the modelled wire rate (one 35-byte packet \
         every (31 + 4) × 10 / baud); the end of the last packet on the simulated wire is \
         taken from a final status read. Efficiency = share of the time the wire carried \
         packets.\n"
    );
    let _ = writeln!(
        o,
        "| baud | packet µs | packets | packets/s | modelled max/s | efficiency | send lateness p99 µs | module decode errors |\n|---|---|---|---|---|---|---|---|"
    );
    for s in &r.streams {
        let _ = writeln!(
            o,
            "| {} | {:.1} | {} | {:.1} | {:.1} | {} | {:.1} | {} |",
            s.baud.bits_per_second(),
            us(s.packet_time),
            s.packets,
            s.rate_hz(),
            1.0 / s.packet_time.as_secs_f64(),
            pct(s.efficiency()),
            Summary::of_us(&s.send_lateness_us).p99,
            s.decode_errors
        );
    }
    let _ = writeln!(o);

    // WHJ free-running.
    let _ = writeln!(o, "## WHJ free-running\n");
    let _ = writeln!(
        o,
        "Client: `robobus::whj::JointBus`, `Joint::command_position` for each joint in turn \
         (each position servo frame answered by its feedback before the next is sent), as \
         fast as it goes, over the in-process memory bus to the simulator thread (wall clock, \
         1 / 5 Mbit/s wire, 20 µs processing delay). Modelled cycle: Σ (command frame + \
         processing delay + feedback frame − one intermission), exact bit-stuffed frame times. \
         Wait: how the client waits (`JointBusConfig::wait`); in the spin rows the simulator \
         serves in its precise mode. Window: whether the client holds each reply for its \
         0.5 ms collision window before crediting it (duplicate detection, on by default); \
         with it a request/reply loop cannot beat one window per transaction, whatever \
         the wire. Simulator late: frames released after their modelled instants (p50 / \
         p99).\n"
    );
    let _ = writeln!(
        o,
        "| joints | link | wait | window | modelled cycle µs | measured mean µs | p99 µs | cycles/s | efficiency | at median cycle | overhead µs/transaction | errors | client CPU µs/cycle | simulator late p50 / p99 |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for f in &r.free {
        let s = Summary::of_us(&f.cycle_us);
        let _ = writeln!(
            o,
            "| {} | {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {} | {} | {:.1} | {} | {:.1} | {} / {} |",
            f.spec.joints,
            f.link,
            f.spec.wait,
            if f.spec.collision_window { "on" } else { "off" },
            us(f.modelled_cycle),
            1e6 / f.rate_hz().max(1e-9),
            s.p99,
            f.rate_hz(),
            pct(f.efficiency()),
            pct(us(f.modelled_cycle) / s.p50.max(1e-9)),
            (1e6 / f.rate_hz().max(1e-9) - us(f.modelled_cycle)) / f64::from(f.spec.joints.max(1)),
            f.errors,
            f.cpu_per_cycle_us(),
            opt_us(f.sim_lateness.and_then(|l| l.p50)),
            opt_us(f.sim_lateness.and_then(|l| l.p99))
        );
        let name = free_plot(f);
        plots.push((
            name.clone(),
            svg::histogram(
                &format!("WHJ free-running cycle, {}, memory bus", f.spec.label()),
                &f.cycle_us,
                &[("model", us(f.modelled_cycle))],
            ),
        ));
    }
    let _ = writeln!(o);
    for f in &r.free {
        let name = free_plot(f);
        let _ = writeln!(o, "![{name}]({name})");
    }
    let _ = writeln!(o);

    // WHJ fixed.
    let _ = writeln!(o, "## WHJ fixed rate\n");
    let _ = writeln!(
        o,
        "Client: `JointBus::cyclic` (position mode, default smoothing) at a fixed period over \
         the memory bus to the simulator thread (1 / 5 Mbit/s wire, 20 µs processing delay). \
         Round trip = first command frame sent → last feedback frame received, measured at \
         the link by a wrapper that matches each feedback frame to the command it answers; \
         a link miss is a cycle whose feedback was not all in before the next cycle's first \
         command. Modelled round trip: commands first (they win arbitration), then the \
         feedback frames back to back; efficiency = modelled / link median. A rate whose \
         modelled round trip exceeds its period cannot be carried by the wire at all (14 \
         joints at 1 kHz: the wire-time model gives 609 Hz at most); commands then queue without \
         bound and that row only shows that it fails; it is left out of the 97 % goal.\n\n\
         The client's own statistics are shown beside them: its deadline misses, and its \
         \"impossible\" round trips, shorter than 98 % of the modelled wire time, which would \
         mean a feedback frame credited to a cycle whose command it cannot have answered \
         (the loop reads every frame already received before each tick and never takes a \
         frame that came before its cycle's command can have been answered, so this should be 0). \
         The client counts a cycle as missed when its last feedback came after the next \
         tick was due, even if the next command went out later; the link counts it \
         against the next command, so after a late tick the client reports more misses.\n"
    );
    let _ = writeln!(
        o,
        "| joints | protocol | wait | rate Hz | cycles | link misses | client misses | client overruns | client impossible RT | modelled RT µs | p50 µs | p99 µs | p99.9 µs | max µs | efficiency | start lateness p99 µs | simulator late p50 / p99 |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for f in &r.fixed {
        let s = Summary::of_us(&f.link_round_trip_us);
        let l = Summary::of_us(&f.lateness_us);
        let _ = writeln!(
            o,
            "| {} | {} | {} | {}{} | {} | {} | {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {} | {:.1} | {} / {} |",
            f.spec.joints,
            proto(f.protocol),
            f.spec.wait,
            f.hz,
            if f.feasible() {
                ""
            } else {
                " (beyond the wire's limit)"
            },
            f.link_cycles,
            f.link_misses,
            f.deadline_misses,
            f.overruns,
            f.impossible,
            us(f.modelled_round_trip),
            s.p50,
            s.p99,
            s.p999,
            s.max,
            pct(f.efficiency()),
            l.p99,
            opt_us(f.sim.stats.lateness.p50),
            opt_us(f.sim.stats.lateness.p99)
        );
        let name = format!(
            "whj_fixed_{}j_{}hz_{}_{}.svg",
            f.spec.joints,
            f.hz,
            match f.protocol {
                Protocol::PointToPoint => "p2p",
                Protocol::Broadcast => "broadcast",
            },
            if f.spec.wait.spins() { "spin" } else { "sleep" }
        );
        plots.push((
            name,
            svg::histogram(
                &format!(
                    "WHJ round trip, {} joints, {} Hz, {}, wait {}",
                    f.spec.joints,
                    f.hz,
                    proto(f.protocol),
                    f.spec.wait
                ),
                &f.link_round_trip_us,
                &[
                    ("model", us(f.modelled_round_trip)),
                    ("period", 1e6 / f64::from(f.hz.max(1))),
                ],
            ),
        ));
    }
    let _ = writeln!(o);
    for (name, _) in plots.iter().filter(|p| p.0.starts_with("whj_fixed")) {
        let _ = writeln!(o, "![{name}]({name})");
    }
    let _ = writeln!(o);

    // Peers.
    let _ = writeln!(o, "## Peers\n");
    let _ = writeln!(
        o,
        "Same run, same simulator endpoint, zero device turnaround. wCK: ours and \
         `scripts/bench/wck_poll_peer.py` (pyserial, prebuilt packets, exact-length reads) \
         on the same pty. WHJ: ours (`JointBus` on `UdpBus`) and \
         `scripts/bench/whj_servo_peer.py` (python-can `udp_multicast`, prebuilt messages) \
         against one simulator process on the UDP multicast bus in a private network \
         namespace; \"wire off\" runs the simulated wire at 1 Gbit/s so that only the \
         clients and the transport are measured. CPU: ours = this process's (wCK: the \
         polling thread's) CPU time, theirs = the Python process's.\n"
    );
    let _ = writeln!(
        o,
        "| loop | ours cycles/s | theirs cycles/s | ours / theirs | ours CPU µs/cycle | theirs CPU µs/cycle | theirs / ours CPU | ours efficiency | errors ours / theirs | simulator late p50 / p99 (ours) |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    for p in &r.polls {
        if let Some(peer) = &p.peer {
            let _ = writeln!(
                o,
                "| wCK polling {} servos, {} bit/s, wait {}, guard {} | {:.1} | {:.1} | {:.2}× | {:.1} | {:.1} | {:.1}× | {} | {} / {} | {} / {} |",
                p.spec.servos,
                p.spec.baud.bits_per_second(),
                p.spec.wait,
                if p.spec.guard { "default" } else { "off" },
                p.rate_hz(),
                peer.rate_hz(),
                p.rate_hz() / peer.rate_hz().max(1e-9),
                p.cpu_per_cycle_us(),
                peer.cpu_per_cycle_us(),
                peer.cpu_per_cycle_us() / p.cpu_per_cycle_us().max(1e-9),
                pct(p.efficiency()),
                p.errors,
                peer.errors,
                opt_us(p.endpoint.lateness.p50),
                opt_us(p.endpoint.lateness.p99)
            );
        }
    }
    for f in &r.udp {
        let eff = if f.spec.fast_wire {
            "–".to_string()
        } else {
            pct(f.efficiency())
        };
        match &f.peer {
            Some(peer) => {
                let _ = writeln!(
                    o,
                    "| WHJ servo cycle {}, UDP, {} | {:.1} | {:.1} | {:.2}× | {:.1} | {:.1} | {:.1}× | {} | {} / {} | {} / {} |",
                    f.spec.label(),
                    if f.spec.fast_wire {
                        "wire off"
                    } else {
                        "1 / 5 Mbit/s wire"
                    },
                    f.rate_hz(),
                    peer.rate_hz(),
                    f.rate_hz() / peer.rate_hz().max(1e-9),
                    f.cpu_per_cycle_us(),
                    peer.cpu_per_cycle_us(),
                    peer.cpu_per_cycle_us() / f.cpu_per_cycle_us().max(1e-9),
                    eff,
                    f.errors,
                    peer.errors,
                    opt_us(f.sim_lateness.and_then(|l| l.p50)),
                    opt_us(f.sim_lateness.and_then(|l| l.p99))
                );
            }
            None => {
                let _ = writeln!(
                    o,
                    "| WHJ servo cycle {}, UDP | {:.1} | – | – | {:.1} | – | – | {} | {} / – | {} / {} |",
                    f.spec.label(),
                    f.rate_hz(),
                    f.cpu_per_cycle_us(),
                    eff,
                    f.errors,
                    opt_us(f.sim_lateness.and_then(|l| l.p50)),
                    opt_us(f.sim_lateness.and_then(|l| l.p99))
                );
            }
        }
    }
    let _ = writeln!(o);

    transport_section(&mut o, r);
    o.push_str(&syscalls_markdown(r));
    telemetry_section(&mut o, r);
    studio_section(&mut o, r);

    // Simulator.
    let _ = writeln!(o, "## Simulator\n");
    let _ = writeln!(
        o,
        "| virtual clock | simulated s | wall s | simulated s per wall s |\n|---|---|---|---|"
    );
    for s in &r.sims {
        let _ = writeln!(
            o,
            "| {} | {:.2} | {:.3} | {:.1} |",
            s.what,
            s.simulated.as_secs_f64(),
            s.wall.as_secs_f64(),
            s.ratio()
        );
    }
    let _ = writeln!(o);
    let _ = writeln!(
        o,
        "Wall clock, real time: the serving thread's CPU share while a client loads it, and \
         what one core could serve at that load (linear extrapolation); the sleeping mode \
         only (in the precise mode the serving thread polls: one core, whatever the load).\n"
    );
    let _ = writeln!(
        o,
        "| endpoint | load | serving thread CPU | served in real time per core |\n|---|---|---|---|"
    );
    for p in r
        .polls
        .iter()
        .filter(|p| p.spec.servos == 31 && !p.spec.wait.spins() && p.spec.guard)
    {
        let share = p.endpoint.cpu.as_secs_f64() / p.endpoint.wall.as_secs_f64().max(1e-9);
        let _ = writeln!(
            o,
            "| wCK pty, 31 servos, {} bit/s, {} turnaround | continuous polling, {:.0} transactions/s; reply bytes late by at most {} µs | {} | {:.0} servos |",
            p.spec.baud.bits_per_second(),
            if p.spec.manual_turnaround {
                "manual"
            } else {
                "zero"
            },
            p.rate_hz() * 31.0,
            p.endpoint.late_max.as_micros(),
            pct(share),
            31.0 / share.max(1e-9)
        );
    }
    for f in r.fixed.iter().filter(|f| {
        f.hz == 1000 && f.protocol == Protocol::PointToPoint && f.feasible() && !f.spec.wait.spins()
    }) {
        let share = f.sim.cpu.as_secs_f64() / f.sim.wall.as_secs_f64().max(1e-9);
        let _ = writeln!(
            o,
            "| WHJ memory bus, {} joints | 1 kHz position servo; frames late by at most {} µs | {} | {:.0} joints at 1 kHz |",
            f.spec.joints,
            f.sim.stats.max_lateness.as_micros(),
            pct(share),
            f64::from(f.spec.joints) / share.max(1e-9)
        );
    }
    let _ = writeln!(o);

    let _ = writeln!(o, "## Method\n");
    let _ = writeln!(
        o,
        "See `BENCHMARKS.md` (method, goals, how to reproduce) and \
         the `timing` modules of `robobus_wck` / `robobus_whj` (the wire-time formulas). \
         Efficiency = modelled wire \
         + device time / measured cycle time."
    );
    o
}

/// A lateness quantile in µs, or "beyond 20 ms" / "–" (nothing released).
pub fn opt_us(d: Option<Duration>) -> String {
    d.map_or_else(
        || "–".to_owned(),
        |d| format!("{:.0} µs", d.as_secs_f64() * 1e6),
    )
}

/// The system-call section: per transaction, the calling thread and the others.
pub fn syscalls_markdown(r: &Results) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "## System calls per transaction
"
    );
    if r.syscalls.is_empty() {
        let _ = writeln!(
            o,
            "Not counted in this run ({}). `robobus-bench syscalls [--udp]` counts them \
             with `strace`.\n",
            if r.smoke {
                "smoke mode"
            } else {
                "`strace` not found"
            }
        );
        return o;
    }
    let _ = writeln!(
        o,
        "Counted with `strace -ff -ttt` on the one-case runners in the sleep mode, between \
         two markers the measured loop leaves in the trace (the Python peers leave the same \
         markers); every thread of the traced process. Ours in the wCK case runs the \
         simulator's endpoint thread in the same process: it is the \"other threads\" column \
         there; a peer's simulator runs outside the trace, and ours over UDP talks to a \
         simulator process as the peer does.\n"
    );
    let _ = writeln!(
        o,
        "| case | transactions | caller per transaction | calls | other threads per transaction | calls |\n|---|---|---|---|---|---|"
    );
    for c in &r.syscalls {
        let t = c.transactions.max(1) as f64;
        let _ = writeln!(
            o,
            "| {} | {} | {:.1} | {} | {:.1} | {} |",
            c.what,
            c.transactions,
            c.caller.total as f64 / t,
            c.caller.per(c.transactions),
            c.others.total as f64 / t,
            c.others.per(c.transactions)
        );
    }
    let _ = writeln!(o);
    o
}

fn free_plot(f: &crate::whj::FreeResult) -> String {
    format!(
        "whj_free_{}j_{}_{}.svg",
        f.spec.joints,
        if f.spec.wait.spins() { "spin" } else { "sleep" },
        if f.spec.collision_window {
            "window"
        } else {
            "nowindow"
        }
    )
}

/// The transports' own round trip, both sides spinning.
fn transport_section(o: &mut String, r: &Results) {
    let _ = writeln!(o, "## Transports\n");
    let Some((pty, memory)) = &r.echo else {
        let _ = writeln!(o, "Not measured.\n");
        return;
    };
    let _ = writeln!(
        o,
        "One byte through the pty and straight back, and one frame through the in-process \
         memory bus and straight back, both sides spinning (`robobus-bench echo`): what \
         each request/reply transaction over that transport costs at the least, whatever \
         the client and the simulator do. A pty hands every write to a kernel worker thread \
         before the other side can read it.\n"
    );
    let _ = writeln!(
        o,
        "| transport | round trips | p50 µs | p99 µs |\n|---|---|---|---|\n| pty | {} | {:.1} | {:.1} |\n| memory bus | {} | {:.1} | {:.1} |\n",
        pty.n, pty.p50, pty.p99, memory.n, memory.p50, memory.p99
    );
}
