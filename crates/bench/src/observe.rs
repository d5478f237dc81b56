//! A frame link wrapper that times the cyclic servo loop at the link: it matches every
//! feedback frame to the command it answers (per joint, in order: the simulated joints
//! answer every command) and so measures each cycle's true round trip, independent of
//! how the client attributes feedback to cycles. A feedback frame counts from the moment
//! it reached the link (its receive timestamp), not from when the client read it.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant, SystemTime};

use robobus_link::{FrameLink, FrameLinkError, IdFilter, Received};
use robobus_whj::{CanFrame, Reply, Request};

/// Commands sent less than this apart belong to one cycle (a tick's burst).
const BURST_GAP: Duration = Duration::from_micros(150);

#[derive(Debug, Clone, Copy)]
struct Burst {
    first_send: Instant,
    expected: usize,
    answered: usize,
    last_answer: Option<Instant>,
}

/// What the observer saw.
#[derive(Debug, Default)]
pub struct Observed {
    bursts: Vec<Burst>,
    /// Per joint (index = ID): commands awaiting feedback, as burst indices.
    waiting: Vec<VecDeque<usize>>,
    last_send: Option<Instant>,
    /// Feedback frames that matched no command.
    pub unmatched: u64,
}

/// One cycle as seen at the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkCycle {
    /// First command → last feedback, if every feedback came.
    pub round_trip: Option<Duration>,
    /// Whether every feedback came before the next cycle's first command.
    pub in_time: bool,
}

impl Observed {
    fn joint_queue(&mut self, id: u8) -> &mut VecDeque<usize> {
        let i = usize::from(id);
        if self.waiting.len() <= i {
            self.waiting.resize_with(i + 1, VecDeque::new);
        }
        &mut self.waiting[i]
    }

    fn sent(&mut self, frame: &CanFrame, at: Instant) {
        let joints: Vec<u8> = match Request::from_frame(frame) {
            Ok(Request::PositionServo { joint, .. }) => vec![joint.get()],
            Ok(Request::BroadcastPosition(b)) => (1..=7u8)
                .filter(|j| robobus_whj::JointId::new(*j).is_ok_and(|id| b.mask.selects(id)))
                .collect(),
            _ => return,
        };
        let new_burst = self
            .last_send
            .is_none_or(|t| at.saturating_duration_since(t) > BURST_GAP);
        self.last_send = Some(at);
        if new_burst {
            self.bursts.push(Burst {
                first_send: at,
                expected: 0,
                answered: 0,
                last_answer: None,
            });
        }
        let b = self.bursts.len() - 1;
        for j in joints {
            if let Some(burst) = self.bursts.last_mut() {
                burst.expected += 1;
            }
            self.joint_queue(j).push_back(b);
        }
    }

    fn received(&mut self, frame: &CanFrame, at: Instant) {
        let joint = match Reply::from_frame(frame) {
            Ok(Reply::ServoFeedback { joint, .. } | Reply::BroadcastFeedback { joint, .. }) => {
                joint.get()
            }
            _ => return,
        };
        match self.joint_queue(joint).pop_front() {
            Some(b) => {
                if let Some(burst) = self.bursts.get_mut(b) {
                    burst.answered += 1;
                    burst.last_answer = Some(at);
                }
            }
            None => self.unmatched += 1,
        }
    }

    /// The cycles seen so far (the last one left out: it may still be running).
    pub fn cycles(&self) -> Vec<LinkCycle> {
        self.bursts
            .windows(2)
            .map(|w| {
                let (b, next) = (w[0], w[1]);
                let complete = b.expected > 0 && b.answered == b.expected;
                let round_trip = if complete {
                    b.last_answer
                        .map(|t| t.saturating_duration_since(b.first_send))
                } else {
                    None
                };
                LinkCycle {
                    round_trip,
                    in_time: complete && b.last_answer.is_some_and(|t| t <= next.first_send),
                }
            })
            .collect()
    }
}

/// Wraps a frame link and records what [`Observed`] needs.
#[derive(Debug)]
pub struct ObservedLink<L> {
    inner: L,
    log: Arc<Mutex<Observed>>,
}

impl<L> ObservedLink<L> {
    /// Wraps `inner`; read the observations through the returned handle.
    pub fn new(inner: L) -> (Self, Arc<Mutex<Observed>>) {
        let log = Arc::new(Mutex::new(Observed::default()));
        (
            Self {
                inner,
                log: Arc::clone(&log),
            },
            log,
        )
    }
}

impl<L: FrameLink> FrameLink for ObservedLink<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        let at = Instant::now();
        self.inner.send(frame)?;
        self.log
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .sent(frame, at);
        Ok(())
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        let r = self.inner.recv(deadline)?;
        let now = Instant::now();
        // When the frame reached the link (the memory bus stamps frames as they are sent),
        // not when the client got round to reading it.
        let at = r
            .timestamp
            .and_then(|ts| SystemTime::now().duration_since(ts).ok())
            .and_then(|age| now.checked_sub(age))
            .unwrap_or(now);
        self.log
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .received(&r.frame, at);
        Ok(r)
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.inner.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(inner);
}
