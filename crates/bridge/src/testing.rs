//! What the bridge's unit tests share: a bridge's shared state armed on the simulated
//! robot, its WHJ joints enabled in position mode, its guard kept fed.

#![allow(clippy::unwrap_used)] // tests: a failed unwrap is a failed test

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::{SESSION, Shared, run_request};

/// Arms `s`, puts its WHJ joints `joints` (`"1-7"`) in position mode and enables them, and
/// starts a thread feeding the guard's heartbeat (as the command thread does) until the
/// returned flag is set.
pub(crate) fn armed(s: Arc<Shared>, joints: &str) -> (Arc<Shared>, Arc<AtomicBool>) {
    s.set_armed(true).unwrap();
    s.guard.heartbeat(SESSION);
    for r in [
        format!(r#"{{"op":"whj.mode","joints":"{joints}","mode":"position"}}"#),
        format!(r#"{{"op":"whj.enable","joints":"{joints}"}}"#),
    ] {
        run_request(&s, &r).unwrap();
    }
    let done = Arc::new(AtomicBool::new(false));
    let (beat, stop) = (Arc::clone(&s), Arc::clone(&done));
    std::thread::spawn(move || {
        while !stop.load(Ordering::SeqCst) {
            beat.guard.heartbeat(SESSION);
            std::thread::sleep(Duration::from_millis(50));
        }
    });
    (s, done)
}
