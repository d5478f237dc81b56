//! A wCK bus owned through an `Arc`, for front ends that hold it from several threads.

use std::sync::{Arc, Mutex, MutexGuard};

use robobus_link::ByteLink;
use robobus_wck::{Position, ServoId, TorqueLevel};

use crate::wck::{Servo, Status, WckBus, WckError};

/// A [`WckBus`] shared between threads (a web server's handlers, a Python binding): clones
/// share the bus; each call locks it for one transaction or one closure.
#[derive(Debug)]
pub struct SharedWckBus<L>(Arc<Mutex<WckBus<L>>>);

impl<L> Clone for SharedWckBus<L> {
    fn clone(&self) -> Self {
        Self(Arc::clone(&self.0))
    }
}

impl<L: ByteLink> SharedWckBus<L> {
    /// Shares `bus`.
    pub fn new(bus: WckBus<L>) -> Self {
        Self(Arc::new(Mutex::new(bus)))
    }

    /// Locks the bus (a panic in another holder does not make it unusable: the bus keeps
    /// no state a half-done transaction could break, each one flushes stale input first).
    pub fn lock(&self) -> MutexGuard<'_, WckBus<L>> {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Runs `f` with the bus locked (an operation of [`crate::ops::wck`], several
    /// transactions in a row).
    pub fn with<R>(&self, f: impl FnOnce(&mut WckBus<L>) -> R) -> R {
        f(&mut self.lock())
    }

    /// A handle on servo `id` that owns a clone of this bus.
    pub fn servo(&self, id: ServoId) -> SharedServo<L> {
        SharedServo {
            bus: self.clone(),
            id,
        }
    }
}

/// A servo handle that owns its bus (an `Arc`), so it can live in another thread or in an
/// object of another language.
#[derive(Debug)]
pub struct SharedServo<L> {
    bus: SharedWckBus<L>,
    id: ServoId,
}

impl<L> Clone for SharedServo<L> {
    fn clone(&self) -> Self {
        Self {
            bus: self.bus.clone(),
            id: self.id,
        }
    }
}

impl<L: ByteLink> SharedServo<L> {
    /// The servo's ID.
    pub const fn id(&self) -> ServoId {
        self.id
    }

    /// Runs `f` on a borrowed [`Servo`] with the bus locked (every typed command).
    pub fn with<R>(&self, f: impl FnOnce(&mut Servo<'_, L>) -> R) -> R {
        let mut bus = self.bus.lock();
        f(&mut bus.servo(self.id))
    }

    /// [`Servo::status`].
    pub fn status(&self) -> Result<Status, WckError> {
        self.bus.lock().servo(self.id).status()
    }

    /// [`Servo::move_to`].
    pub fn move_to(&self, torque: TorqueLevel, position: Position) -> Result<Status, WckError> {
        self.bus.lock().servo(self.id).move_to(torque, position)
    }

    /// [`Servo::passive`].
    pub fn passive(&self) -> Result<Position, WckError> {
        self.bus.lock().servo(self.id).passive()
    }
}
