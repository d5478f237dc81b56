//! What the station's buses can carry, computed from their timing (not measured): how long
//! one joint state sample and one command take on the wire, bus by bus, and so the
//! highest state and command rates. The bridge says at start when the rate asked is more
//! than the buses carry, and its health repeats it.

use std::time::Duration;

use robobus::ops::Family;
use robobus::station::Station;
use robobus::station::follow::FollowedJoint;
use robobus_wck::{Command, Position, ServoId, TorqueLevel};
use robobus_whj::timing::{BitRates, frame_duration};
use robobus_whj::{CanFrame, JointId, Request};
use serde::Serialize;

/// WHJ transactions of one joint's sample: a status query and a speed read.
const WHJ_SAMPLE_TRANSACTIONS: u32 = 2;
/// The largest WHJ reply (a status or a servo feedback: 16 data bytes).
const WHJ_REPLY_BYTES: usize = 16;

/// One bus of the robot file, as the bridge uses it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BusTiming {
    /// The bus.
    pub name: String,
    /// `wck` or `whj`.
    pub family: Family,
    /// Its joints in the robot file.
    pub joints: usize,
    /// One sample of its joints on the wire, ms (wCK: a status read per servo, each with
    /// the client's reply guard after the reply; WHJ: a status query and a speed read per
    /// joint, each reply held one reply frame and the link's allowance for a second
    /// answer while the duplicate check is on).
    pub sample_ms: f64,
    /// One command to its joints on the wire, ms (wCK: a position move per servo with its
    /// guard; WHJ: a position servo frame per joint with its hold).
    pub command_ms: f64,
}

/// The buses' limits: how many samples and commands a second their timing carries.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Capacity {
    /// Each bus of the robot file.
    pub buses: Vec<BusTiming>,
}

impl Capacity {
    /// The timing of the buses `joints` are on.
    pub fn of(station: &Station, joints: &[FollowedJoint]) -> Self {
        let mut buses: Vec<BusTiming> = Vec::new();
        for j in joints {
            let i = buses
                .iter()
                .position(|b| b.name == j.bus)
                .unwrap_or_else(|| {
                    buses.push(BusTiming {
                        name: j.bus.clone(),
                        family: j.family,
                        joints: 0,
                        sample_ms: 0.0,
                        command_ms: 0.0,
                    });
                    buses.len() - 1
                });
            let (sample, command) = match j.family {
                Family::Wck => wck_joint(station, &j.bus, j.id),
                _ => whj_joint(station, &j.bus, j.id),
            };
            let b = &mut buses[i];
            b.joints += 1;
            b.sample_ms += sample.as_secs_f64() * 1e3;
            b.command_ms += command.as_secs_f64() * 1e3;
        }
        Self { buses }
    }

    /// One sample of every joint, ms: the slowest bus's, as `robot.sample` reads the
    /// buses at the same time, one thread each.
    pub fn sample_ms(&self) -> f64 {
        self.buses.iter().map(|b| b.sample_ms).fold(0.0, f64::max)
    }

    /// One command to every joint, ms: the joints are stepped one after the other.
    pub fn command_ms(&self) -> f64 {
        self.buses.iter().map(|b| b.command_ms).sum()
    }

    /// The highest joint state rate the buses carry, Hz (`None`: no joint).
    pub fn states_hz(&self) -> Option<f64> {
        let ms = self.sample_ms();
        (ms > 0.0).then(|| 1e3 / ms)
    }

    /// The highest command rate the buses carry with no state sampled, Hz.
    pub fn commands_hz(&self) -> Option<f64> {
        let ms = self.command_ms();
        (ms > 0.0).then(|| 1e3 / ms)
    }

    /// What to tell the user when `rate_hz` is more than the buses carry; `None` when
    /// they carry it.
    pub fn note(&self, rate_hz: f64) -> Option<String> {
        let limit = self.states_hz()?;
        (rate_hz > limit).then(|| {
            format!(
                "the buses carry at most {limit:.1} Hz of joint states, not the {rate_hz} Hz \
                 asked (one sample is {:.1} ms on the wire, its slowest bus's; the buses are \
                 read at the same time: {}); states are published as fast as the buses allow, \
                 and the health counts the samples lost",
                self.sample_ms(),
                self.buses
                    .iter()
                    .map(|b| format!("{} {} joints {:.1} ms", b.name, b.joints, b.sample_ms))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
    }
}

/// One wCK servo's status read and position move on `bus`, each with the reply guard.
fn wck_joint(station: &Station, bus: &str, id: u8) -> (Duration, Duration) {
    let (Ok(port), Ok(id)) = (station.wck(Some(bus)), ServoId::new(id)) else {
        return (Duration::ZERO, Duration::ZERO);
    };
    let b = port.lock();
    let baud = b.baud();
    let guard = b.config().guard_at(baud);
    drop(b);
    let read = robobus_wck::timing::transaction_time(&Command::StatusRead { id }, baud) + guard;
    let mv = match (TorqueLevel::new(2), Position::new(127)) {
        (Ok(torque), Ok(position)) => {
            robobus_wck::timing::transaction_time(
                &Command::Move {
                    id,
                    torque,
                    position,
                },
                baud,
            ) + guard
        }
        _ => read,
    };
    (read, mv)
}

/// One WHJ joint's sample and servo frame on `bus`.
fn whj_joint(station: &Station, bus: &str, id: u8) -> (Duration, Duration) {
    let (Ok(port), Ok(joint)) = (station.whj(Some(bus)), JointId::new(id)) else {
        return (Duration::ZERO, Duration::ZERO);
    };
    // The duplicate check's allowance for the link's lateness (`None`: the check is off).
    let check = port.bus().duplicate_check();
    let rates = BitRates::WHJ;
    let reply = CanFrame::standard_id(0x500 + u16::from(id))
        .and_then(|i| CanFrame::new_fd_padded(i, &[0; WHJ_REPLY_BYTES]))
        .map_or(Duration::ZERO, |f| frame_duration(&f, rates));
    // A transaction: the request, the reply, and the reply held for a second answer
    // (an arbitration loser's frame and the link's allowance) while the check is on.
    let transaction = |r: Request| {
        frame_duration(&r.to_frame(), rates) + reply + check.map_or(Duration::ZERO, |a| reply + a)
    };
    let sample = transaction(Request::StatusQuery { joint }) * WHJ_SAMPLE_TRANSACTIONS;
    let command = robobus_whj::units::Position::from_degrees(0.0)
        .map_or(sample / WHJ_SAMPLE_TRANSACTIONS, |target| {
            transaction(Request::PositionServo { joint, target })
        });
    (sample, command)
}
