//! The report's telemetry section: the station's shared sampling with one and with eight
//! subscribers.

use std::fmt::Write as _;

use crate::{Results, telemetry};

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

pub(super) fn telemetry_section(o: &mut String, r: &Results) {
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
