//! The one sampling of a bus that its subscribers share ([`Station::telemetry`]; see the
//! [telemetry module's docs](super)).

use std::collections::BTreeSet;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::{
    Delivery, Queue, Reading, Report, Request, Sample, Speeds, StreamStats, Subscriber, Taking,
    check_capacity, check_stream, devices_of, take_sample,
};
use crate::ops::{OpError, StopToken};
use crate::station::Station;

/// `report` with the rows of `devices` only, its failure summed up from them.
fn rows_of(report: &Report, devices: Option<&BTreeSet<u64>>) -> Report {
    let Some(devices) = devices else {
        return report.clone();
    };
    // Every row is the member's (it asked for the whole union): as it is.
    if report
        .results
        .iter()
        .all(|row| row["id"].as_u64().is_some_and(|id| devices.contains(&id)))
    {
        return report.clone();
    }
    let results: Vec<serde_json::Value> = report
        .results
        .iter()
        .filter(|row| row["id"].as_u64().is_some_and(|id| devices.contains(&id)))
        .cloned()
        .collect();
    let failures: Vec<crate::ops::DeviceResult<u64, ()>> = results
        .iter()
        .filter_map(|row| {
            let kind = serde_json::from_value::<crate::ErrorKind>(row.get("kind")?.clone()).ok()?;
            Some(crate::ops::DeviceResult::failed(
                0,
                crate::ops::Failure::of(kind, &row["error"].as_str().unwrap_or("")),
            ))
        })
        .collect();
    let errors: Vec<String> = results
        .iter()
        .filter(|row| row.get("kind").is_some())
        .filter_map(|row| row["error"].as_str().map(str::to_owned))
        .collect();
    let mut out = Report::with_rows(&report.op, &report.bus, results);
    out.summary.clone_from(&report.summary);
    if let Some(kind) = crate::ops::worst_kind(&failures) {
        out.failed = Some(kind);
        out.error = Some(errors.join("; "));
    }
    out
}

/// What one sample read: the devices and whether the broadcast status.
#[derive(Debug)]
struct Read {
    devices: BTreeSet<u64>,
    broadcast: bool,
}

/// One subscriber of a shared sampling.
#[derive(Debug)]
struct Member {
    id: u64,
    /// Its devices (`None`: the request's every row).
    devices: Option<BTreeSet<u64>>,
    broadcast: bool,
    period: Duration,
    /// When its next sample is due (`None`: at once).
    due: Option<Instant>,
    /// Samples given to it (or lost from its queue) so far.
    seq: u64,
    /// It leaves after this many samples (`None`: when it is dropped or closed).
    limit: Option<u64>,
    queue: Arc<Queue>,
}

#[derive(Debug, Default)]
struct Members {
    list: Vec<Member>,
    next_id: u64,
    /// The last subscriber left: the sampling ends, no one joins it any more.
    stopping: bool,
}

/// The one sampling of a bus that its subscribers share (see the [module docs](self)).
#[derive(Debug)]
struct Shared {
    members: Mutex<Members>,
    /// Rings when a subscriber joins or the last one leaves.
    changed: Condvar,
    stop: StopToken,
    thread: Mutex<Option<JoinHandle<StreamStats>>>,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Members> {
        self.members
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Removes member `id` (its queue ends; it may have left at its limit already);
    /// whether no member is left (the sampling stops).
    fn leave(&self, id: u64) -> bool {
        let mut m = self.lock();
        if let Some(k) = m.list.iter().position(|s| s.id == id) {
            m.list.remove(k).queue.end();
        }
        let last = m.list.is_empty();
        if last {
            m.stopping = true;
            self.stop.stop();
        }
        drop(m);
        self.changed.notify_all();
        last
    }

    /// What the next sample reads: the union of the members' devices, whether any asked
    /// for the broadcast status, the shortest period; `None` once stopping.
    fn plan(&self) -> Option<(BTreeSet<u64>, bool, Duration)> {
        let m = self.lock();
        if m.stopping {
            return None;
        }
        let period = m.list.iter().map(|s| s.period).min()?;
        let devices = m
            .list
            .iter()
            .flat_map(|s| s.devices.iter().flatten().copied())
            .collect();
        Some((devices, m.list.iter().any(|s| s.broadcast), period))
    }

    /// Gives `sample`, taken for the sampling's `slot`, to every member whose turn it is,
    /// each its own rows. A member whose devices (or broadcast status) the sample did not
    /// read, one that joined while it was taken or queued, waits for the next one rather
    /// than being given a sample without its rows.
    fn deliver(&self, sample: &Sample, slot: Instant, period: Duration, read: &Read) {
        let mut m = self.lock();
        for s in &mut m.list {
            let covered = s
                .devices
                .as_ref()
                .is_none_or(|d| d.is_subset(&read.devices))
                && (read.broadcast || !s.broadcast);
            if !covered {
                continue;
            }
            // A slot up to half the sampling's period before the member's turn is on time.
            if s.due.is_some_and(|d| slot + period / 2 < d) {
                continue;
            }
            s.due = Some(match s.due {
                Some(d) if d + s.period > slot => d + s.period,
                _ => slot + s.period,
            });
            let mine = Sample {
                seq: s.seq,
                report: sample
                    .report
                    .as_ref()
                    .map(|r| rows_of(r, s.devices.as_ref())),
                ..sample.clone()
            };
            s.seq += 1;
            s.queue.push(Arc::new(mine));
        }
        // A member given its limit of samples leaves (its queue ends after them).
        let before = m.list.len();
        m.list.retain(|s| {
            let done = s.limit.is_some_and(|n| s.seq >= n);
            if done {
                s.queue.end();
            }
            !done
        });
        if m.list.len() < before {
            if m.list.is_empty() {
                m.stopping = true;
                self.stop.stop();
            }
            drop(m);
            self.changed.notify_all();
        }
    }

    /// Waits until the slot after `base` at the shortest period now (at once if that has
    /// passed) and returns it; `None` when stopping.
    fn wait_slot(&self, base: Instant) -> Option<Instant> {
        let mut m = self.lock();
        loop {
            if m.stopping {
                return None;
            }
            let period = m.list.iter().map(|s| s.period).min()?;
            let now = Instant::now();
            let next = base + period;
            if now >= next {
                return Some(next);
            }
            m = self
                .changed
                .wait_timeout(m, next - now)
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
    }

    fn run(&self, station: &Station, reading: &Reading) -> StreamStats {
        let (tx, rx) = std::sync::mpsc::sync_channel::<(Sample, Instant, Duration, Read)>(4);
        let stats = std::thread::scope(|scope| {
            // The subscribers are served by a thread of their own while the next read is
            // under way (in order, at most 4 samples behind; without that thread, here).
            let delivering = std::thread::Builder::new()
                .name("robobus-deliver".into())
                .spawn_scoped(scope, move || {
                    for (sample, slot, period, read) in rx {
                        self.deliver(&sample, slot, period, &read);
                    }
                })
                .is_ok();
            let tx = delivering.then_some(tx);
            let mut stats = StreamStats::default();
            let mut speeds = matches!(reading, Reading::Wck { .. }).then(Speeds::default);
            let mut slot = Instant::now();
            while let Some((devices, broadcast, period)) = self.plan() {
                let late = Instant::now().saturating_duration_since(slot) > period;
                let taking = Taking {
                    station,
                    reading,
                    devices: &devices,
                    broadcast,
                };
                let sample = take_sample(&taking, &self.stop, speeds.as_mut(), late, &mut stats);
                let read = Read { devices, broadcast };
                match &tx {
                    Some(tx) => {
                        if let Err(e) = tx.send((sample, slot, period, read)) {
                            let (sample, slot, period, read) = e.0;
                            self.deliver(&sample, slot, period, &read);
                        }
                    }
                    None => self.deliver(&sample, slot, period, &read),
                }
                match self.wait_slot(slot) {
                    // Behind: start again from now rather than bursting to catch up.
                    Some(next) if late => slot = next.max(Instant::now()),
                    Some(next) => slot = next,
                    None => break,
                }
            }
            // Everything taken is delivered before the subscribers' queues end.
            drop(tx);
            stats
        });
        let mut m = self.lock();
        m.stopping = true;
        for s in &m.list {
            s.queue.end();
        }
        m.list.clear();
        stats
    }
}

/// A subscription to the shared sampling of a bus ([`Station::telemetry`]): a
/// [`Subscriber`] (its queue: `recv_timeout`, `try_recv`, `queued`, `lost`) that leaves
/// the sampling when dropped or [closed](Subscription::close).
#[derive(Debug)]
pub struct Subscription {
    subscriber: Subscriber,
    shared: Arc<Shared>,
    id: u64,
    request: Request,
    left: bool,
}

impl Subscription {
    /// The request it asked for.
    pub const fn request(&self) -> &Request {
        &self.request
    }

    /// A second handle on its queue (the same samples: each is received by one of
    /// them), for a receiver that outlives its membership: after the subscription is
    /// closed or dropped it receives what is queued, then the end.
    pub fn receiver(&self) -> Subscriber {
        Subscriber {
            queue: Arc::clone(&self.subscriber.queue),
        }
    }

    /// Leaves the sampling (what is queued can still be received, then the end); if no
    /// subscriber is left, stops the sampling, waits until its read under way has
    /// completed and returns what the sampling did (`None`: others still read it, or it
    /// was closed before). What this subscription was given: [`Subscriber::stats`].
    pub fn close(&mut self) -> Option<StreamStats> {
        if std::mem::replace(&mut self.left, true) {
            return None;
        }
        if !self.shared.leave(self.id) {
            return None;
        }
        let thread = self
            .shared
            .thread
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        thread.and_then(|t| t.join().ok())
    }
}

impl std::ops::Deref for Subscription {
    type Target = Subscriber;

    fn deref(&self) -> &Subscriber {
        &self.subscriber
    }
}

/// Every sample until the subscription's stream ends.
impl Iterator for Subscription {
    type Item = Delivery;

    fn next(&mut self) -> Option<Delivery> {
        self.subscriber.next()
    }
}

impl Drop for Subscription {
    fn drop(&mut self) {
        // Never waits: the sampling's thread ends on its own after its read under way.
        if !self.left {
            self.shared.leave(self.id);
        }
    }
}

impl Station {
    /// A subscription to the one sampling of the bus `request` reads (see the [module
    /// docs](crate::catalogue::telemetry)): `request` a reading request (`whj.sample`,
    /// `wck.sample`, `robot.sample`, `whj.status`, `wck.status`, `whj.can-health`), its
    /// rows given at `rate_hz` ([`RATE_HZ`](crate::catalogue::telemetry::RATE_HZ)) into a
    /// queue of `capacity` (1..=[`MAX_QUEUE`](crate::catalogue::telemetry::MAX_QUEUE))
    /// samples. The sampling starts with the first subscription of its bus and reading,
    /// and stops with the last.
    ///
    /// # Errors
    ///
    /// Bad input naming the value and the allowed range: not a reading request, a rate or
    /// capacity out of range, a request that does not validate, a bus the station does
    /// not have; nothing is read then. A thread that cannot be started: a device error.
    pub fn telemetry(
        self: &Arc<Self>,
        request: Request,
        rate_hz: f64,
        capacity: usize,
    ) -> Result<Subscription, OpError> {
        self.telemetry_limited(request, rate_hz, capacity, None)
    }

    /// [`Station::telemetry`] for `limit` samples at most (`None`: until it is dropped or
    /// closed): the subscription leaves the sampling after its `limit`-th sample (counted
    /// as [`Delivery::sample`]'s `seq` is: lost ones too), and its queue ends after it.
    ///
    /// # Errors
    ///
    /// Those of [`Station::telemetry`], and a `limit` of 0.
    pub fn telemetry_limited(
        self: &Arc<Self>,
        request: Request,
        rate_hz: f64,
        capacity: usize,
        limit: Option<u64>,
    ) -> Result<Subscription, OpError> {
        check_capacity(capacity)?;
        if limit == Some(0) {
            return Err(OpError::invalid(
                "limit",
                0,
                "out of range (allowed: at least 1 sample, or none for no limit)",
            ));
        }
        let reading = check_stream(self, &request, rate_hz)?;
        let devices = devices_of(&request)?;
        let broadcast = matches!(&request, Request::WhjSample(r) if r.broadcast);
        let key = reading.key();
        let queue = Arc::new(Queue::new(capacity));
        let mut streams = self.streams();
        streams.retain(|_, w| w.strong_count() > 0);
        let member = |id| Member {
            id,
            devices: devices.clone(),
            broadcast,
            period: Duration::from_secs_f64(1.0 / rate_hz),
            due: None,
            seq: 0,
            limit,
            queue: Arc::clone(&queue),
        };
        let running = streams
            .get(&key)
            .and_then(std::sync::Weak::upgrade)
            .and_then(|a| a.downcast::<Shared>().ok());
        if let Some(shared) = running {
            let mut m = shared.lock();
            if !m.stopping {
                let id = m.next_id;
                m.next_id += 1;
                m.list.push(member(id));
                drop(m);
                shared.changed.notify_all();
                return Ok(Subscription {
                    subscriber: Subscriber { queue },
                    shared,
                    id,
                    request,
                    left: false,
                });
            }
        }
        let shared = Arc::new(Shared {
            members: Mutex::new(Members {
                list: vec![member(0)],
                next_id: 1,
                stopping: false,
            }),
            changed: Condvar::new(),
            stop: StopToken::new(),
            thread: Mutex::new(None),
        });
        let thread = {
            let (shared, station) = (Arc::clone(&shared), Arc::clone(self));
            std::thread::Builder::new()
                .name("robobus-sampler".into())
                .spawn(move || shared.run(&station, &reading))
                .map_err(|e| OpError::Device(format!("starting the sampler thread: {e}")))?
        };
        *shared
            .thread
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(thread);
        let erased: Arc<dyn std::any::Any + Send + Sync> = Arc::clone(&shared) as _;
        streams.insert(key, Arc::downgrade(&erased));
        Ok(Subscription {
            subscriber: Subscriber { queue },
            shared,
            id: 0,
            request,
            left: false,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // tests

    use super::*;

    fn sample_of(ids: &[u64]) -> Sample {
        let rows = ids
            .iter()
            .map(|id| serde_json::json!({"id": id, "position_deg": 1.5}))
            .collect();
        Sample {
            seq: 0,
            unix_ms: 0.0,
            read_ms: 0.0,
            late: false,
            report: Some(Report::with_rows("whj.sample", "arm", rows)),
            sampled_by: None,
            failed: None,
            error: None,
            at: None,
        }
    }

    #[test]
    fn a_member_is_given_only_the_samples_that_read_its_devices() {
        let shared = Shared {
            members: Mutex::new(Members::default()),
            changed: Condvar::new(),
            stop: StopToken::new(),
            thread: Mutex::new(None),
        };
        let queue = Arc::new(Queue::new(8));
        let period = Duration::from_millis(10);
        shared.lock().list.push(Member {
            id: 0,
            devices: Some(BTreeSet::from([1])),
            broadcast: false,
            period,
            due: None,
            seq: 0,
            limit: None,
            queue: Arc::clone(&queue),
        });
        let sub = Subscriber {
            queue: Arc::clone(&queue),
        };
        let read = |devices: &[u64], broadcast| Read {
            devices: devices.iter().copied().collect(),
            broadcast,
        };
        // Taken before it joined, for joint 2 alone: not its sample (not an empty one).
        let now = Instant::now();
        shared.deliver(&sample_of(&[2]), now, period, &read(&[2], false));
        assert_eq!(sub.queued(), 0);
        // The next one read joints 1 and 2: its row, as sample 0.
        shared.deliver(&sample_of(&[1, 2]), now, period, &read(&[1, 2], false));
        let d = sub.try_recv().unwrap();
        assert_eq!(d.sample.seq, 0);
        let rows = &d.sample.report.as_ref().unwrap().results;
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0]["id"], 1);
        // A member that asked for the broadcast status waits for a sample that read it.
        shared.lock().list[0].broadcast = true;
        shared.lock().list[0].due = None;
        shared.deliver(&sample_of(&[1]), now, period, &read(&[1], false));
        assert_eq!(sub.queued(), 0);
        shared.deliver(&sample_of(&[1]), now, period, &read(&[1], true));
        assert_eq!(sub.queued(), 1);
    }
}
