//! The bridge's position command thread (the newest `NS/joint_commands` command,
//! followed whole, the guard's heartbeat, the hold when the stream goes quiet) and its
//! joint state thread (`NS/joint_states`, after the commands): see the [crate docs](crate).

use std::sync::PoisonError;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use robobus::catalogue::Request;

use crate::{HOLD_REASON, SESSION, Shared, bump, cdr, health};

/// The command thread: follows the newest command, keeps the guard's heartbeat, and
/// holds the joints when the stream goes quiet.
pub(crate) fn commands(s: &Shared) {
    let timeout = s.config.command_timeout;
    let tick = (timeout / 4).clamp(Duration::from_millis(5), Duration::from_millis(50));
    let mut last: Option<Instant> = None;
    while !s.stop.is_stopped() {
        let next = {
            let inbox = s.mailbox.inbox();
            let (mut inbox, _) = s
                .mailbox
                .ready
                .wait_timeout_while(inbox, tick, |m| m.newest.is_none() && !s.stop.is_stopped())
                .unwrap_or_else(PoisonError::into_inner);
            let next = inbox.newest.take();
            // The state sampler stays off the buses until this one is applied.
            inbox.applying = next.is_some();
            next
        };
        if s.armed() {
            s.guard.heartbeat(SESSION);
        }
        if let Some((payload, at)) = next {
            // A command that waited longer than the timeout (the buses were slower than
            // the stream) is stale: the stream may have ended since, so it moves nothing.
            let waited = at.elapsed();
            if waited > timeout {
                s.hold_command(
                    &s.counters.commands_stale,
                    format!(
                        "joint_commands: waited {} ms, longer than the command timeout {} ms \
                         (the buses were busy): nothing was sent",
                        waited.as_millis(),
                        timeout.as_millis()
                    ),
                );
            } else if follow(s, &payload) {
                last = Some(at);
                s.status.streaming.store(true, Ordering::SeqCst);
            }
            s.mailbox.inbox().applying = false;
            s.mailbox.ready.notify_all();
        }
        if let Some(t) = last
            && t.elapsed() > timeout
            && s.status.streaming.swap(false, Ordering::SeqCst)
        {
            bump(&s.counters.holds);
            let _ = s.guard.hold(SESSION, HOLD_REASON, t + timeout);
            last = None;
        }
    }
}

/// The joint state thread: one `robot.sample` per slot of the rate asked, published as a
/// `JointState`, after the commands (see the [crate docs](crate)): it does not start a
/// sample while a command waits or is applied, nor when a steady stream's next command is
/// due before the sample would end. Every slot not sampled is counted lost.
pub(crate) fn states(s: &Shared, publisher: &zenoh::pubsub::Publisher<'static>) {
    let request = Request::RobotSample(robobus::catalogue::robot::Sample {});
    let period = Duration::from_secs_f64(1.0 / s.config.rate_hz);
    // What a sample costs: the buses' timing until one was measured.
    let mut cost = Duration::from_secs_f64(s.capacity.sample_ms() / 1e3);
    let mut slot = Instant::now();
    let mut deferred = false;
    while !s.stop.is_stopped() {
        let now = Instant::now();
        // Every whole period that passed since the slot, waiting for the buses or the
        // commands, is a sample lost.
        let behind = now.saturating_duration_since(slot).as_nanos() / period.as_nanos().max(1);
        if behind > 0 {
            let n = u32::try_from(behind).unwrap_or(u32::MAX);
            s.states.lose(
                u64::from(n),
                if deferred {
                    health::LOST_TO_COMMANDS
                } else {
                    health::LOST_TO_BUSES
                },
            );
            slot += period * n;
        }
        if now < slot {
            let inbox = s.mailbox.inbox();
            let _ = s
                .mailbox
                .ready
                .wait_timeout_while(inbox, slot - now, |_| {
                    !s.stop.is_stopped() && Instant::now() < slot
                })
                .unwrap_or_else(PoisonError::into_inner);
            continue;
        }
        // The commands first.
        let wait = {
            let inbox = s.mailbox.inbox();
            let due = inbox.next_due().filter(|&(due, every)| {
                s.status.streaming.load(Ordering::SeqCst)
                    && now + cost > due
                    && now < due + every / 2
            });
            if inbox.applying || inbox.newest.is_some() {
                Some(now + period)
            } else {
                due.map(|(due, every)| due + every / 2)
            }
        };
        if let Some(until) = wait {
            deferred = true;
            let inbox = s.mailbox.inbox();
            let _ = s
                .mailbox
                .ready
                .wait_timeout(inbox, until.saturating_duration_since(Instant::now()))
                .unwrap_or_else(PoisonError::into_inner);
            continue;
        }
        deferred = false;
        let start = Instant::now();
        let outcome = robobus::catalogue::run(
            &s.station,
            &request,
            &mut robobus::ops::Control::new(&s.stop),
        );
        let done = Instant::now();
        cost = done.saturating_duration_since(start);
        let unix_ms = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64() * 1e3);
        health::publish_sample(s, outcome.ok().as_ref(), unix_ms, done, publisher);
        slot += period;
    }
}

/// One command: decoded, checked whole, admitted, applied. Whether it was applied.
pub(crate) fn follow(s: &Shared, payload: &[u8]) -> bool {
    let c = &s.counters;
    let msg = match cdr::Float64MultiArray::decode(payload) {
        Ok(m) => m,
        Err(e) => {
            s.refuse(&c.refused_malformed, format!("joint_commands: {e}"));
            return false;
        }
    };
    let Some(follower) = &s.follower else {
        s.hold_command(
            &c.refused_out_of_range,
            "joint_commands: the station has no robot file".into(),
        );
        return false;
    };
    if let Some(why) = s.drives.blocks_positions() {
        s.hold_command(&c.refused_out_of_range, why);
        return false;
    }
    if let Err(r) = s.admission.check_motion(s.arming(), "joint_commands") {
        s.hold_command(&c.refused_not_armed, r.to_string());
        return false;
    }
    let plan = match follower.plan(&msg.data) {
        Ok(p) => p,
        Err(e) => {
            s.hold_command(&c.refused_out_of_range, format!("joint_commands: {e}"));
            return false;
        }
    };
    for j in follower.joints() {
        if let Err(r) = s
            .admission
            .admit_jog(s.arming(), j.family, Some(&j.bus), j.id)
        {
            s.hold_command(&c.refused_not_armed, format!("joint_commands: {r}"));
            return false;
        }
    }
    let results = follower.apply(&s.station, &plan);
    let failed: Vec<String> = results
        .iter()
        .filter_map(|r| match &r.outcome {
            robobus::ops::Outcome::Failed(f) => Some(format!("{}: {}", r.id, f.error)),
            robobus::ops::Outcome::Ok(_) => None,
        })
        .collect();
    c.joint_failures
        .fetch_add(failed.len() as u64, Ordering::Relaxed);
    if let Some(first) = failed.first() {
        tracing::debug!("command: {} joints failed, first {first}", failed.len());
    }
    bump(&c.commands_applied);
    true
}
