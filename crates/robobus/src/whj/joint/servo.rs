//! Servo frames to many joints at once: [`JointBus::servo_many`], the one path every
//! servo frame of a [`Joint`](super::Joint) takes too.

use robobus_whj::{Reply, Request, ServoFeedback};

use super::super::session::{Attempt, describe};
use crate::whj::bus::within_batch;
use crate::whj::error::attempt_error;
use crate::whj::{JointBus, WhjError};

impl JointBus {
    /// One servo frame (position, speed or current) to each of several joints,
    /// pipelined: all are queued at once and each goes out as soon as its reply ID is
    /// free, so the frames to the other joints go out while each reply is held for a
    /// second answer from a duplicate node, instead of one hold after another. Each frame
    /// has the retry policy of [`Joint::command_position`](super::Joint::command_position);
    /// each joint's feedback (or its failure) is in request order, credited only to its
    /// own frame.
    ///
    /// Every position target is first measured against its joint's actual position
    /// (the latest telemetry, or a status query where that is older than 100 ms): one
    /// further than [`JointBusConfig::step_limit_deg`](crate::whj::JointBusConfig::step_limit_deg)
    /// refuses the whole batch ([`WhjError::StepTooLarge`]) with no frame of it sent. A request
    /// that is not a servo frame to one joint, or more than [`MAX_PIPELINED`](crate::whj::MAX_PIPELINED) of them,
    /// is [`WhjError::InvalidConfig`], with nothing sent.
    pub fn servo_many(
        &self,
        requests: &[Request],
    ) -> Result<Vec<Result<ServoFeedback, WhjError>>, WhjError> {
        within_batch(requests.len(), "servo frames")?;
        let limit = self.config().step_limit_deg;
        // One snapshot of the telemetry for every step check (a status read only for a
        // joint whose position in it is older than 100 ms).
        let mut telemetry = None;
        let mut joints = Vec::with_capacity(requests.len());
        for request in requests {
            match *request {
                Request::PositionServo { joint, target } => {
                    joints.push(joint);
                    let telemetry = telemetry.get_or_insert_with(|| self.telemetry());
                    let actual = self.joint_unchecked(joint).recent_position_in(telemetry)?;
                    if (target.degrees() - actual.degrees()).abs() > limit {
                        return Err(WhjError::StepTooLarge {
                            joint,
                            from_deg: actual.degrees(),
                            to_deg: target.degrees(),
                            limit_deg: limit,
                        });
                    }
                }
                Request::SpeedServo { joint, .. } | Request::CurrentServo { joint, .. } => {
                    joints.push(joint);
                }
                other => {
                    return Err(WhjError::InvalidConfig {
                        reason: format!("not a servo frame to one joint: {other:?}"),
                    });
                }
            }
        }
        let attempts = self.config().retries.saturating_add(1);
        let outcomes = self.transact_many(requests, attempts)?;
        Ok(outcomes
            .into_iter()
            .zip(requests.iter().zip(joints))
            .map(|(outcome, (request, joint))| {
                let outcome = outcome?;
                match outcome.attempt {
                    Attempt::Reply {
                        reply: Reply::ServoFeedback { feedback, .. },
                    } => Ok(feedback),
                    Attempt::Reply { reply } if !matches!(reply, Reply::CmdErr { .. }) => {
                        Err(WhjError::BadReply {
                            joint,
                            request: describe(request),
                            reason: format!("unexpected reply {reply:?}"),
                            attempts: outcome.attempts,
                        })
                    }
                    last => Err(attempt_error(joint, request, last, outcome.attempts)),
                }
            })
            .collect())
    }
}
