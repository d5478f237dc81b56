//! The report's bridge section (`## Bridge`): the latency, loss, rate and CPU of the many
//! bridges' run, and the built-in robot's runs.

use std::fmt::Write as _;

use super::{BUILTIN_SHARE_OF_LIMIT, BridgeResult, BuiltinRun, DRAIN, JOINTS, SETTLE};
use crate::Machine;
use crate::stats::Summary;

fn ms(us: f64) -> String {
    format!("{:.2}", us / 1e3)
}

fn pct(x: f64) -> String {
    format!("{:.1} %", 100.0 * x)
}

fn pct2(x: f64) -> String {
    format!("{:.2} %", 100.0 * x)
}

/// The report's bridge section (`## Bridge`), on `machine`.
#[allow(clippy::too_many_lines)] // one section, table by table
pub fn markdown(r: Option<&BridgeResult>, machine: &Machine) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "## Bridge\n");
    let Some(r) = r else {
        let _ = writeln!(o, "Not run.\n");
        return o;
    };
    let period_us = r.spec.period().as_secs_f64() * 1e6;
    let asked = r.spec.rate_hz;
    let windowed = r.capacity.states_hz().unwrap_or(f64::INFINITY);
    let _ = writeln!(
        o,
        "{} `robobus-bridge`s in one process, each on its own station of {JOINTS} simulated \
         WHJ30 joints (in-process memory bus, 1 / 5 Mbit/s wire, 20 µs processing delay, \
         wall clock) under the namespaces `bot0`..`bot{}`, asked for joint states at \
         {asked:.0} Hz, each a Zenoh client of one router (a session in router mode on \
         `{}`, scouting off) in the same process; one subscriber on `*/joint_states`, also \
         a client of the router, decodes every message. \
         Window {:.1} s, after every bridge delivered and a {:.1} s warm-up. Everything \
         shares the machine's cores.\n",
        r.bots.len(),
        r.bots.len().saturating_sub(1),
        r.router,
        r.wall.as_secs_f64(),
        r.spec.warmup.as_secs_f64()
    );
    let _ = writeln!(
        o,
        "- **Latency**: the subscriber's wall clock in its callback − the message's \
         `header.stamp` (when the bus read of the sample completed); ratios against the \
         sample period asked for, {:.1} ms.\n\
         - **Loss**: per bridge, over the whole run (from its start), the states it \
         counted as published (`Bridge::health().states.published`) against the messages \
         the subscriber received. After the window every station's bus link is closed \
         (a pass-through wrapper around the memory-bus endpoint until then), so every \
         later sample fails at once and nothing more is published; the counts are taken \
         once none has moved for {:.1} s{}, and after a further {:.1} s drain, so both \
         are exact.\n\
         - **Rate**: states published a second per bridge, against the asked {asked:.0} Hz \
         and the bus's limit for one sample stream as the bridge computes it from the \
         bus's timing (`Bridge::capacity`): one sample of {JOINTS} joints is a status \
         query and a speed read per joint, each reply held one frame and the link's \
         allowance for a second answer, {:.3} ms on the wire: **{windowed:.1} samples/s** \
         at most, all other costs zero. The stamp interval (between consecutive messages \
         of a bridge) is how long one sample took: its bus read, or the wait for its \
         slot.\n",
        period_us / 1e3,
        SETTLE.as_secs_f64(),
        if r.settled {
            ""
        } else {
            " (**they did not settle**: the loss counts are not exact)"
        },
        DRAIN.as_secs_f64(),
        r.capacity.sample_ms(),
    );
    let (lat, gaps) = (r.latencies(), r.intervals());
    let rates: Vec<f64> = r.bots.iter().map(|b| b.rate_hz(r.wall)).collect();
    let mut sorted = rates.clone();
    sorted.sort_by(f64::total_cmp);
    let median = crate::stats::percentile(&sorted, 0.5);
    let (lo, hi) = (
        sorted.first().copied().unwrap_or(0.0),
        sorted.last().copied().unwrap_or(0.0),
    );
    let published = r.published();
    let (total, missing) = (r.published_total(), r.missing());
    let _ = writeln!(
        o,
        "| bridges × joints | rate per bridge, Hz (min / median / max) | median / asked | median / bus limit | stamp interval p50 / p99, ms | published / received, whole run | missing (loss) | latency p50 / p99 / max, ms | p50 / period | p99 / period |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    let _ = writeln!(
        o,
        "| {} × {JOINTS} | {lo:.1} / {median:.1} / {hi:.1} | {:.3}× | {:.3}× | {} / {} | {total} / {} | {missing} ({}) | {} / {} / {} | {:.2}× | {:.2}× |\n",
        r.bots.len(),
        median / asked,
        median / windowed.max(1e-9),
        ms(gaps.p50),
        ms(gaps.p99),
        r.received_total(),
        pct2(missing as f64 / (total as f64).max(1.0)),
        ms(lat.p50),
        ms(lat.p99),
        ms(lat.max),
        lat.p50 / period_us,
        lat.p99 / period_us,
    );
    let _ = writeln!(
        o,
        "Per bridge: published and received in the window (received: stamped in it; a \
         message stamped just before a cut can be counted published just after it), the \
         whole run's counts and loss, the window's rate and latencies, and what the \
         bridge's health counted in the window: messages with fewer than {JOINTS} joints \
         received, joints left out, samples failed whole, samples its publisher did not \
         keep up with.\n"
    );
    let _ = writeln!(
        o,
        "| bridge | window: published / received | run: published / received | loss | rate Hz | rate / asked | p50 ms | p99 ms | p50 / period | p99 / period | partial messages | joints left out | failed / lost samples |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for (b, rate) in r.bots.iter().zip(&rates) {
        let l = Summary::of_us(&b.latency_us);
        let _ = writeln!(
            o,
            "| {} | {} / {} | {} / {} | {} | {rate:.1} | {:.3}× | {} | {} | {:.2}× | {:.2}× | {} | {} | {} / {} |",
            b.namespace,
            b.published,
            b.received,
            b.published_total,
            b.received_total,
            pct2(b.loss()),
            rate / asked,
            ms(l.p50),
            ms(l.p99),
            l.p50 / period_us,
            l.p99 / period_us,
            b.partial,
            b.joints_left_out,
            b.failed_samples,
            b.lost_samples,
        );
    }
    let _ = writeln!(o);
    if r.undecodable > 0 {
        let _ = writeln!(
            o,
            "{} payloads on `*/joint_states` did not decode as a `JointState`.\n",
            r.undecodable
        );
    }
    builtin_markdown(&mut o, &r.builtin);
    let joints = r.joints().max(1) as f64;
    let _ = writeln!(
        o,
        "**CPU** over the window, as a share of one core (the machine has {} logical CPUs): \
         the whole process (`getrusage`); of it the simulators' serving threads, the \
         bridges' own threads (`robobus-*`: telemetry, states, health, commands, queries, \
         guard; `whj-bus`) and this benchmark's waiting thread (`/proc/self/task/*/stat`, \
         10 ms ticks); the rest is the Zenoh runtime that the {} bridges' sessions, the \
         router and the subscriber share in this process. Per joint: divided by the {} \
         joints; per joint-sample: divided by the {} states published × {JOINTS} joints.\n",
        machine.cpus,
        r.bots.len(),
        r.joints(),
        published
    );
    let _ = writeln!(
        o,
        "| what | share of a core | per joint | CPU µs per joint-sample |\n|---|---|---|---|"
    );
    for (what, d) in [
        ("process", r.process_cpu),
        (
            "bridges + router + subscriber (process − simulators − bench thread)",
            r.bridging_cpu(),
        ),
        ("of it, the bridges' own threads", r.bridge_threads_cpu),
        ("of it, the Zenoh runtime", r.zenoh_cpu()),
        ("simulators", r.sims_cpu),
    ] {
        let _ = writeln!(
            o,
            "| {what} | {} | {} | {:.1} |",
            pct(r.share(d)),
            pct2(r.share(d) / joints),
            r.per_joint_sample_us(d)
        );
    }
    let _ = writeln!(o);
    o
}

/// The built-in robot's rows.
fn builtin_markdown(o: &mut String, runs: &[BuiltinRun]) {
    let Some(first) = runs.first() else {
        return;
    };
    let c = &first.capacity;
    let _ = writeln!(
        o,
        "**The built-in robot**: one bridge on `Station::simulated_live` (16 wCK servos at \
         115200 bit/s and 7 WHJ30 joints, wall clock), no command stream, in the same \
         process, asked for the bridge's default rate and for {:.0} % of its buses' limit. \
         The limit is the bridge's own (`Bridge::capacity`, said at start and in the \
         health): one sample is {:.1} ms on the wire ({}; the buses read at the same \
         time, the slowest sets it), so **{:.1} Hz** at most. Rate: states published in the window a second; \
         lost: the slots of the rate asked its health counted without a sample.\n",
        BUILTIN_SHARE_OF_LIMIT * 100.0,
        c.sample_ms(),
        c.buses
            .iter()
            .map(|b| format!("{}: {} joints, {:.1} ms", b.name, b.joints, b.sample_ms))
            .collect::<Vec<_>>()
            .join("; "),
        first.limit_hz(),
    );
    let _ = writeln!(
        o,
        "| asked, Hz | bus limit, Hz | published, Hz | / asked | / bus limit | / reachable (min of both) | achieved (health, last 2 s) | lost slots / window | failed samples |\n|---|---|---|---|---|---|---|---|---|"
    );
    for b in runs {
        let rate = b.rate_hz();
        let _ = writeln!(
            o,
            "| {:.1} | {:.1} | {rate:.1} | {:.3}× | {:.3}× | **{:.3}×** | {} | {} / {:.1} s | {} |",
            b.asked_hz,
            b.limit_hz(),
            rate / b.asked_hz,
            rate / b.limit_hz(),
            rate / b.reachable_hz(),
            b.achieved_hz
                .map_or_else(|| "-".to_owned(), |h| format!("{h:.1} Hz")),
            b.lost,
            b.wall.as_secs_f64(),
            b.failed,
        );
    }
    let _ = writeln!(o);
}
