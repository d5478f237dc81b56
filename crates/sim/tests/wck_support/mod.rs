//! Helpers shared by the wCK simulator tests.
#![allow(dead_code, unreachable_pub, clippy::unwrap_used)]

use core::time::Duration;

use robobus_sim::wck::{Bus, BusConfig, Model, VirtualHost};
use robobus_wck::{Command, Position, ServoId, TorqueLevel};

/// Past the 65 ms a module is deaf after power-up.
pub const AWAKE: Duration = Duration::from_millis(70);

/// A host on a bus with one module per ID (defaults, shaft at 127), awake.
pub fn host(model: Model, ids: &[u8]) -> VirtualHost {
    host_with(
        BusConfig {
            max_skew: Duration::ZERO,
            ..BusConfig::default()
        },
        model,
        ids,
    )
}

/// Like [`host`] with a configuration.
pub fn host_with(config: BusConfig, model: Model, ids: &[u8]) -> VirtualHost {
    let bus = Bus::with_servos(config, model, ids.iter().copied());
    let mut h = VirtualHost::new(bus);
    h.sleep(AWAKE);
    h
}

pub fn id(n: u8) -> ServoId {
    ServoId::new(n).unwrap()
}

pub fn mv(n: u8, torque: u8, position: u8) -> Command {
    Command::Move {
        id: id(n),
        torque: TorqueLevel::new(torque).unwrap(),
        position: Position::new(position).unwrap(),
    }
}

pub fn status(h: &mut VirtualHost, n: u8) -> Option<(u8, u8)> {
    match h.command(&Command::StatusRead { id: id(n) })[..] {
        [load, pos] => Some((load, pos)),
        _ => None,
    }
}

/// Polls servo `n` every `period` until its position is within `tol` of `target`;
/// returns the elapsed time, or None after `limit`.
pub fn time_to_reach(
    h: &mut VirtualHost,
    n: u8,
    target: u8,
    tol: u8,
    period: Duration,
    limit: Duration,
) -> Option<Duration> {
    let start = h.now();
    while h.now().saturating_sub(start) < limit {
        if let Some((_, pos)) = status(h, n)
            && pos.abs_diff(target) <= tol
        {
            return Some(h.now().saturating_sub(start));
        }
        h.sleep(period);
    }
    None
}
