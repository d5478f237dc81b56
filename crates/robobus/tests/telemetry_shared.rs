//! One sampler per bus, shared: every subscription to a bus's readings
//! (`Station::telemetry`) is served by the one sampling of that bus. On the simulators'
//! virtual clocks, with the frames counted at the simulated bus.

#![allow(clippy::unwrap_used, clippy::panic, clippy::expect_used)]

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use robobus::catalogue::telemetry::{Delivery, RecvError, Subscription};
use robobus::catalogue::{self, Request};
use robobus::ops::Control;
use robobus::station::sampler::SampledBy;
use robobus::station::{Station, WhjPort};
use robobus::whj::{CyclicConfig, JointBus, JointBusConfig};
use robobus_sim::whj::{WhjBus, WhjModel, WhjSimHandle, WhjSimLink};
use robobus_whj::JointId;
use robobus_whj::units::Position;

/// Frames of one `whj.sample` of one joint: its status query and its speed read.
const FRAMES_PER_JOINT: u64 = 2;

/// WHJ joints `1..=n` on the bus `arm`, on the virtual clock, each connected and its
/// limits read once already (what a first sample costs).
fn station(n: u8) -> (Arc<Station>, WhjPort, WhjSimHandle) {
    let (link, sim) = WhjSimLink::new(WhjBus::chain(1..=n, WhjModel::Whj30, 11));
    let bus = JointBus::open_with(link, JointBusConfig::default()).unwrap();
    let mut s = Station::new();
    let port = s.add_whj("arm", bus);
    s.keep(Box::new(std::sync::Mutex::new(sim.clone())));
    let warm = request(&format!("1-{n}"));
    catalogue::run(&s, &warm, &mut Control::none()).unwrap();
    (Arc::new(s), port, sim)
}

fn request(joints: &str) -> Request {
    Request::parse_many(&format!(r#"{{"op": "whj.sample", "joints": "{joints}"}}"#))
        .unwrap()
        .remove(0)
}

/// Frames the host has sent on the simulated bus.
fn host_frames(sim: &WhjSimHandle) -> u64 {
    sim.with_bus(|b| b.stats().host_frames)
}

fn next(sub: &Subscription) -> Delivery {
    sub.recv_timeout(Duration::from_secs(10))
        .expect("a sample within 10 s")
}

/// Every delivery until the subscription's end; fails past `at_most` of them.
fn until_end(sub: &Subscription, at_most: usize) -> Vec<Delivery> {
    let mut got = Vec::new();
    loop {
        match sub.recv_timeout(Duration::from_secs(10)) {
            Ok(d) => got.push(d),
            Err(RecvError::Ended) => return got,
            Err(RecvError::Timeout) => panic!("no sample and no end within 10 s"),
        }
        assert!(got.len() <= at_most, "{} samples and no end", got.len());
    }
}

/// The joint IDs of a delivery's rows.
fn ids(d: &Delivery) -> Vec<u64> {
    d.sample
        .report
        .as_ref()
        .expect("a report")
        .results
        .iter()
        .map(|r| r["id"].as_u64().unwrap())
        .collect()
}

/// `n` samples from each subscription; each is only its own joints' rows, numbered 0, 1,
/// 2, ... with nothing lost.
fn read_each(subs: &[(Subscription, Vec<u64>)], n: u64) {
    for (sub, joints) in subs {
        for k in 0..n {
            let d = next(sub);
            assert_eq!(d.lost, 0);
            assert_eq!(d.sample.seq, k);
            assert_eq!(&ids(&d), joints);
            assert_eq!(d.sample.sampled_by, Some(SampledBy::Pipelined));
            let report = d.sample.report.as_ref().unwrap();
            assert!(report.failed.is_none(), "{report:?}");
        }
    }
}

#[test]
fn eight_subscribers_cost_the_bus_the_frames_one_does() {
    for subscribers in [1usize, 8] {
        let (station, _port, sim) = station(7);
        let before = host_frames(&sim);
        // One subscriber of joints 1-7; or that one, and one of each joint alone.
        let mut asked = vec!["1-7".to_owned()];
        asked.extend((1..subscribers).map(|k| k.to_string()));
        let subs: Vec<(Subscription, Vec<u64>)> = asked
            .iter()
            .map(|joints| {
                let sub = station.telemetry(request(joints), 200.0, 4096).unwrap();
                let ids = match joints.as_str() {
                    "1-7" => (1..=7).collect(),
                    one => vec![one.parse().unwrap()],
                };
                (sub, ids)
            })
            .collect();
        read_each(&subs, 20);
        // Every subscription leaves; the last one's close ends the sampling and says
        // what it took.
        let mut stats = None;
        for (mut sub, _) in subs {
            if let Some(s) = sub.close() {
                assert!(stats.is_none(), "one sampling only");
                stats = Some(s);
            }
        }
        let stats = stats.expect("the last close returns the sampling's stats");
        assert!(stats.samples >= 20, "{stats:?}");
        assert_eq!(stats.failed, 0);
        // One status query and one speed read per joint of the union (1-7) per sample,
        // however many subscribers: the bus carries one sampling.
        assert_eq!(
            host_frames(&sim) - before,
            stats.samples * 7 * FRAMES_PER_JOINT,
            "{subscribers} subscribers, {stats:?}"
        );
    }
}

#[test]
fn the_last_unsubscribe_stops_the_bus_traffic() {
    let (station, _port, sim) = station(2);
    let mut a = station.telemetry(request("1"), 200.0, 64).unwrap();
    let mut b = station.telemetry(request("2"), 200.0, 64).unwrap();
    next(&a);
    next(&b);
    // One of two leaves: the other still gets samples, of its own joint.
    assert!(a.close().is_none());
    let before = host_frames(&sim);
    for _ in 0..3 {
        assert_eq!(ids(&next(&b)), [2]);
    }
    assert!(host_frames(&sim) > before);
    // The last leaves: the sampling stops once its read under way is done, and the bus
    // carries nothing more.
    let stats = b.close().expect("the last subscriber stops the sampling");
    let stopped = host_frames(&sim);
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(host_frames(&sim), stopped, "{stats:?}");
    // Joining again starts a new sampling, numbered from 0.
    let mut c = station.telemetry(request("1-2"), 200.0, 64).unwrap();
    assert_eq!(next(&c).sample.seq, 0);
    assert_eq!(ids(&next(&c)), [1, 2]);
    assert!(c.close().is_some());
}

#[test]
fn a_subscriber_at_a_lower_rate_gets_every_nth_sample_of_the_bus() {
    let (station, _port, _sim) = station(2);
    let fast = station.telemetry(request("1"), 100.0, 4096).unwrap();
    next(&fast);
    let slow = station.telemetry(request("2"), 25.0, 4096).unwrap();
    // 100 Hz against 25 Hz: four of the bus's samples for each of the slow one's.
    let mut fast_seen = 0u64;
    let mut slow_seen = 0u64;
    while slow_seen < 5 {
        let d = next(&slow);
        assert_eq!(ids(&d), [2]);
        assert_eq!(d.sample.seq, slow_seen);
        slow_seen += 1;
        while let Ok(f) = fast.try_recv() {
            assert_eq!(ids(&f), [1]);
            fast_seen += 1;
        }
    }
    drop(slow);
    let mut fast = fast;
    let stats = fast.close().unwrap();
    while let Ok(f) = fast.try_recv() {
        assert_eq!(ids(&f), [1]);
        fast_seen += 1;
    }
    // Every sample of the bus went to the fast subscriber (the first one before the loop
    // above); the slow one's five span at least 1 + 4 * 4 of them.
    assert_eq!(fast_seen + 1, stats.samples, "{stats:?}");
    assert!(stats.samples > 4 * 4, "{stats:?}");
}

#[test]
fn a_sample_taken_from_cyclic_feedback_says_so() {
    let (station, port, sim) = station(2);
    let sub = station.telemetry(request("1-2"), 200.0, 64).unwrap();
    assert_eq!(next(&sub).sample.sampled_by, Some(SampledBy::Pipelined));
    let bus = port.bus();
    let joints: Vec<JointId> = (1..=2).map(|j| JointId::new(j).unwrap()).collect();
    let at: Vec<Position> = joints
        .iter()
        .map(|&j| bus.joint_unchecked(j).status().unwrap().position)
        .collect();
    let cyc = bus
        .cyclic(CyclicConfig::position(
            joints.clone(),
            Duration::from_millis(2),
        ))
        .unwrap();
    cyc.set_positions(&at).unwrap();
    // Samples begun before the loop ran may still be queued: the first from the loop.
    let d = (0..100)
        .map(|_| next(&sub))
        .find(|d| d.sample.sampled_by == Some(SampledBy::Cyclic))
        .expect("a sample from the loop's feedback");
    let report = d.sample.report.as_ref().unwrap();
    assert!(report.failed.is_none(), "{report:?}");
    for (row, p) in report.results.iter().zip(&at) {
        let got = row["position_deg"].as_f64().unwrap();
        assert!((got - p.degrees()).abs() < 0.01, "{row}");
    }
    // From the loop, no status query or speed read goes out (4 frames a sample): only
    // the loop's, one servo frame per joint per 2 ms cycle (the two counters are read one
    // after the other while the loop runs: one cycle of slack).
    let before = host_frames(&sim);
    let cycles_before = cyc.stats().cycles;
    for _ in 0..5 {
        assert_eq!(next(&sub).sample.sampled_by, Some(SampledBy::Cyclic));
    }
    let sent = host_frames(&sim) - before;
    let cycled = cyc.stats().cycles - cycles_before;
    assert!(
        sent.abs_diff(cycled * 2) <= 2,
        "{sent} frames in {cycled} cycles"
    );
    drop(sub);
    cyc.stop();
}

#[test]
fn a_silent_joint_is_a_failed_row_for_every_subscriber_never_an_old_value() {
    let (station, _port, sim) = station(3);
    let subs: Vec<Subscription> = ["1-3", "2", "2-3"]
        .iter()
        .map(|j| station.telemetry(request(j), 100.0, 4096).unwrap())
        .collect();
    for sub in &subs {
        let d = next(sub);
        let rep = d.sample.report.as_ref().unwrap();
        assert!(rep.failed.is_none(), "{rep:?}");
    }
    sim.with_bus(|b| {
        let now = b.now();
        b.joint_mut(2).unwrap().fall_silent(now);
    });
    for sub in &subs {
        let mut silent_since = None;
        for k in 0..40 {
            let d = next(sub);
            let rep = d.sample.report.as_ref().unwrap();
            let row = rep
                .results
                .iter()
                .find(|r| r["id"] == 2)
                .expect("joint 2's row");
            if row.get("kind").is_some() {
                assert_eq!(row["kind"], "no-device", "{row}");
                assert!(row.get("position_deg").is_none(), "{row}");
                assert_eq!(rep.failed.map(robobus::ErrorKind::name), Some("no-device"));
                silent_since.get_or_insert(k);
            } else {
                // Once silent, never a value again (an old one least of all).
                assert!(silent_since.is_none(), "joint 2 had a value at {k}: {row}");
            }
            // The other joints answer on.
            for r in rep.results.iter().filter(|r| r["id"] != 2) {
                assert!(r["position_deg"].is_number(), "{r}");
            }
        }
        assert!(silent_since.is_some_and(|k| k < 10), "{silent_since:?}");
    }
    let failed: BTreeSet<bool> = subs.into_iter().map(|mut s| s.close().is_some()).collect();
    assert!(failed.contains(&true));
}

#[test]
fn a_limited_subscription_leaves_after_its_count_and_says_what_it_was_given() {
    let (station, _port, sim) = station(2);
    let before = host_frames(&sim);
    let mut other = station.telemetry(request("2"), 200.0, 4096).unwrap();
    next(&other);
    let mut limited = station
        .telemetry_limited(request("1"), 200.0, 4096, Some(4))
        .unwrap();
    // Its four samples, numbered 0..=3, then the end; what it was given.
    let got = until_end(&limited, 10);
    let seqs: Vec<u64> = got.iter().map(|d| d.sample.seq).collect();
    assert_eq!(seqs, [0, 1, 2, 3]);
    assert!(got.iter().all(|d| ids(d) == [1]));
    let stats = limited.stats();
    assert_eq!((stats.samples, stats.failed), (4, 0), "{stats:?}");
    let late = got.iter().filter(|d| d.sample.late).count();
    assert_eq!(stats.late, u64::try_from(late).unwrap());
    // It left the sampling: the other reads on, its own joint.
    for _ in 0..20 {
        assert_eq!(ids(&next(&other)), [2]);
    }
    assert!(limited.close().is_none(), "the other still reads");
    let sampling = other.close().expect("the last subscriber's close");
    // Joint 2 was read in every sample; joint 1 in the limited one's four and at most
    // the reads begun before its fourth was delivered (the delivery runs up to 6 behind).
    let joint_reads = (host_frames(&sim) - before) / FRAMES_PER_JOINT;
    let joint1 = joint_reads - sampling.samples;
    assert!(
        (4..=4 + 6).contains(&joint1),
        "{joint1} reads of joint 1, {sampling:?}"
    );
    // The other was given every sample but those under way when it left.
    let given = other.stats().samples;
    assert!(
        given <= sampling.samples && sampling.samples <= given + 6,
        "{given} {sampling:?}"
    );
}

#[test]
fn the_last_limited_subscription_stops_the_sampling_at_its_count() {
    let (station, _port, sim) = station(2);
    let before = host_frames(&sim);
    let mut sub = station
        .telemetry_limited(request("1-2"), 200.0, 64, Some(3))
        .unwrap();
    assert_eq!(until_end(&sub, 10).len(), 3);
    // Its close joins the sampling, which took the three and at most the ones under way
    // in the delivery (4) after them; then the bus is quiet.
    let stats = sub.close().expect("the sampling's own stats");
    assert!((3..=3 + 4).contains(&stats.samples), "{stats:?}");
    let quiet = host_frames(&sim);
    assert_eq!(quiet - before, stats.samples * 2 * FRAMES_PER_JOINT);
    std::thread::sleep(Duration::from_millis(50));
    assert_eq!(host_frames(&sim), quiet);
    assert_eq!(sub.stats().samples, 3);
}

#[test]
fn a_limit_of_zero_is_refused_naming_it() {
    let (station, _port, sim) = station(1);
    let before = host_frames(&sim);
    let e = station
        .telemetry_limited(request("1"), 100.0, 64, Some(0))
        .unwrap_err();
    assert_eq!(e.kind(), robobus::ErrorKind::BadInput);
    let text = e.to_string();
    assert!(
        text.contains("limit") && text.contains("at least 1"),
        "{text}"
    );
    assert_eq!(host_frames(&sim), before);
}
