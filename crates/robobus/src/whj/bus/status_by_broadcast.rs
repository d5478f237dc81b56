//! Status queries on a link that cannot send a frame without data (mjbots' fdcanusb): WHJ's
//! point-to-point status query (`0x600+ID`) has no data bytes, so the joints are asked
//! with the broadcast status query (0x7F) instead, and each joint's 24-byte broadcast
//! feedback, which holds every value of the status feedback, answers its request.
//!
//! Only joints 1..=7 have a broadcast slot; a status query to another joint fails on the
//! host, naming why, with nothing sent. One broadcast frame asks every joint of a batch
//! (the smallest reply mask that selects them all; joints it selects beyond them answer
//! too and are not credited), again for those that did not answer in the reply timeout,
//! up to the request's attempts. A second, different answer from one joint within the
//! collision window credits neither, as on the point-to-point path.

use core::time::Duration;
use std::time::Instant;

use robobus_whj::broadcast::{BroadcastStatus, ReplyMask};
use robobus_whj::timing::{BitRates, frame_duration};
use robobus_whj::{BroadcastFeedback, JointId, JointStatus, Reply, Request};

use super::JointBus;
use crate::whj::error::WhjError;
use crate::whj::session::{Attempt, Outcome};

/// The longest one wait for broadcast replies lasts before it looks again.
const LOOK_EVERY: Duration = Duration::from_millis(1);

/// The status feedback a broadcast feedback carries.
fn status_of(f: &BroadcastFeedback) -> JointStatus {
    JointStatus {
        error: f.error,
        voltage: f.voltage,
        temperature: f.temperature,
        enable: u8::from(f.is_enabled()),
        brake: u8::from(f.brake_locked()),
        position: f.position,
        current: Some(f.current),
    }
}

/// The smallest reply mask that selects every joint of `joints` (all with a broadcast
/// slot).
fn mask_for(joints: &[JointId]) -> Option<ReplyMask> {
    (0..=0xFu8)
        .filter_map(|code| ReplyMask::new(code).ok())
        .filter(|m| joints.iter().all(|j| m.selects(*j)))
        .min_by_key(|m| m.joints().count())
}

impl JointBus {
    /// [`JointBus::run`] for a batch with status queries on a link that cannot send them:
    /// the other requests through the session, the status queries by broadcast.
    pub(super) fn run_status_by_broadcast(
        &self,
        requests: &[Request],
        timeout: Duration,
        quiet_after: Duration,
        attempts: u32,
    ) -> Result<Vec<Result<Outcome, WhjError>>, WhjError> {
        let is_status = |r: &Request| matches!(r, Request::StatusQuery { .. });
        let others: Vec<(usize, Request)> = requests
            .iter()
            .enumerate()
            .filter(|(_, r)| !is_status(r))
            .map(|(i, r)| (i, *r))
            .collect();
        let mut out: Vec<Option<Result<Outcome, WhjError>>> =
            requests.iter().map(|_| None).collect();
        if !others.is_empty() {
            let batch: Vec<Request> = others.iter().map(|(_, r)| *r).collect();
            let done = self.run_session(&batch, timeout, quiet_after, attempts)?;
            for ((i, _), o) in others.iter().zip(done) {
                if let Some(slot) = out.get_mut(*i) {
                    *slot = Some(o);
                }
            }
        }
        let joints: Vec<(usize, JointId)> = requests
            .iter()
            .enumerate()
            .filter(|(_, r)| is_status(r))
            .filter_map(|(i, r)| r.joint().map(|j| (i, j)))
            .collect();
        for (i, result) in self.status_by_broadcast(&joints, timeout, attempts.max(1)) {
            if let Some(slot) = out.get_mut(i) {
                *slot = Some(result);
            }
        }
        Ok(out
            .into_iter()
            .map(|o| o.unwrap_or_else(|| Err(self.closed_error())))
            .collect())
    }

    /// Asks `joints` (each with its request's index) for their status by broadcast; one
    /// outcome per joint.
    fn status_by_broadcast(
        &self,
        joints: &[(usize, JointId)],
        timeout: Duration,
        attempts: u32,
    ) -> Vec<(usize, Result<Outcome, WhjError>)> {
        let mut done: Vec<(usize, Result<Outcome, WhjError>)> = Vec::new();
        let mut pending: Vec<(usize, JointId)> = Vec::new();
        for &(i, j) in joints {
            if j.has_broadcast_slot() {
                pending.push((i, j));
            } else {
                done.push((
                    i,
                    Err(WhjError::Link {
                        detail: format!(
                            "joint {j}: this link cannot send the status query (0x600+ID, a \
                             frame without data), and the broadcast status query that asks \
                             instead reaches joints 1..=7 only"
                        ),
                    }),
                ));
            }
        }
        let mut made = 0;
        while !pending.is_empty() && made < attempts {
            made += 1;
            let ids: Vec<JointId> = pending.iter().map(|(_, j)| *j).collect();
            let Some(mask) = mask_for(&ids) else {
                break;
            };
            let request = Request::BroadcastStatus(BroadcastStatus::new(mask));
            let sent = match self.send_broadcast(request) {
                Ok(at) => at,
                Err(e) => {
                    let attempt = |_: &JointId| match &e {
                        WhjError::InvalidConfig { .. } => Attempt::Busy,
                        other => Attempt::Link(other.to_string()),
                    };
                    done.extend(pending.drain(..).map(|(i, j)| {
                        (
                            i,
                            Ok(Outcome {
                                attempt: attempt(&j),
                                attempts: made,
                            }),
                        )
                    }));
                    break;
                }
            };
            let answers = self.collect_status(sent, &ids, timeout);
            let mut still = Vec::new();
            for ((i, j), answer) in pending.drain(..).zip(answers) {
                match answer {
                    Some(attempt) => done.push((
                        i,
                        Ok(Outcome {
                            attempt,
                            attempts: made,
                        }),
                    )),
                    None => still.push((i, j)),
                }
            }
            pending = still;
        }
        let state = self.telemetry().bus.state;
        done.extend(pending.into_iter().map(|(i, _)| {
            (
                i,
                Ok(Outcome {
                    attempt: Attempt::Timeout {
                        waited: timeout,
                        state,
                    },
                    attempts: made,
                }),
            )
        }));
        done
    }

    /// Waits up to `timeout` after `sent` for each joint's broadcast feedback; each
    /// joint's attempt (`None`: no answer).
    fn collect_status(
        &self,
        sent: Instant,
        joints: &[JointId],
        timeout: Duration,
    ) -> Vec<Option<Attempt>> {
        let deadline = sent + timeout;
        let check = self.duplicate_check();
        let window = check.unwrap_or_default();
        let answers_of = |got: &[(Instant, robobus_whj::CanFrame)], id: JointId| {
            got.iter()
                .filter_map(|(at, f)| match Reply::from_frame(f) {
                    Ok(Reply::BroadcastFeedback { joint, feedback }) if joint == id => Some((
                        *at,
                        Reply::Status {
                            joint,
                            status: status_of(&feedback),
                        },
                    )),
                    _ => None,
                })
                .collect::<Vec<_>>()
        };
        loop {
            let got = self.broadcast_replies_since(sent);
            let now = self.now();
            let answers: Vec<Vec<(Instant, Reply)>> =
                joints.iter().map(|&j| answers_of(&got, j)).collect();
            // Every joint answered, and a second node at any of their IDs, which lost
            // arbitration to every answer on the bus (a lower ID wins), would have sent
            // its own by now: one frame after the last one received, plus the link's
            // allowance (`JointBus::duplicate_check`). Or the time is up.
            let last = got.last().map(|(at, f)| {
                at.checked_add(frame_duration(f, BitRates::WHJ) + window)
                    .unwrap_or(*at)
            });
            let settled = answers.iter().all(|a| !a.is_empty())
                && (check.is_none() || last.is_some_and(|t| now >= t));
            if settled || now >= deadline {
                return answers
                    .into_iter()
                    .map(|a| {
                        let mut it = a.into_iter().map(|(_, r)| r);
                        let first = it.next()?;
                        Some(match it.find(|r| *r != first) {
                            Some(second) => Attempt::Duplicate { first, second },
                            None => Attempt::Reply { reply: first },
                        })
                    })
                    .collect();
            }
            self.sleep_until(deadline.min(now + LOOK_EVERY));
        }
    }
}
