//! The Markdown report with its SVG plots.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use robobus::whj::Protocol;

use crate::codec::{describe, us};
use crate::stats::Summary;
use crate::{BenchError, Results, svg, wck};

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

mod studio_section;
mod system_section;
mod telemetry_section;

pub use studio_section::studio_markdown;
use studio_section::studio_section;
pub use system_section::syscalls_markdown;
use system_section::transport_section;
use telemetry_section::telemetry_section;
pub use telemetry_section::{telemetry_markdown, telemetry_ratios};

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
                    "WHJ servo cycle {}, {}, {} (python-can)",
                    f.spec.label(),
                    f.link,
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
         (each position servo frame answered by its feedback before the next is sent), or, \
         on a `pipelined` link, one `JointBus::servo_many` batch a cycle (every frame sent \
         at once, each feedback credited to its own frame), as fast as it goes, over the \
         in-process memory bus to the simulator thread (wall clock, 1 / 5 Mbit/s wire, 20 µs \
         processing delay). Modelled cycle: Σ (command frame + processing delay + feedback \
         frame − one intermission), exact bit-stuffed frame times; pipelined, the commands \
         back to back, then the feedback. Wait: how the client waits \
         (`JointBusConfig::wait`); in the spin rows the simulator serves in its precise \
         mode. Window: whether the client holds each reply for a second answer from a \
         duplicate node (an arbitration loser's frame plus the link's allowance; on by \
         default) before crediting it; joint after joint, a loop pays it per transaction, \
         pipelined only the last reply's is waited out alone. Simulator late: frames \
         released after their modelled instants (p50 / p99).\n"
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
                    "| WHJ servo cycle {}, {}, {} | {:.1} | {:.1} | {:.2}× | {:.1} | {:.1} | {:.1}× | {} | {} / {} | {} / {} |",
                    f.spec.label(),
                    f.link,
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
                    "| WHJ servo cycle {}, {} | {:.1} | – | – | {:.1} | – | – | {} | {} / – | {} / {} |",
                    f.spec.label(),
                    f.link,
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

fn free_plot(f: &crate::whj::FreeResult) -> String {
    format!(
        "whj_free_{}j{}_{}_{}.svg",
        f.spec.joints,
        if f.link.ends_with("pipelined") {
            "_pipelined"
        } else {
            ""
        },
        if f.spec.wait.spins() { "spin" } else { "sleep" },
        if f.spec.collision_window {
            "window"
        } else {
            "nowindow"
        }
    )
}
