//! The device handle: one typed method per command of the manual's appendix A-1.

use robobus_link::ByteLink;
use robobus_wck::program::Program;
use robobus_wck::{
    Accel, BaudRate, Boundaries, Command, DGain, DataByte, ExtServoId, IGain, IoBits, Load,
    MotionCount, Overload, PGain, Position, Position10, Reply, Rotation, ServoId, Speed,
    TorqueLevel, WheelSpeed,
};

use super::bus::WckBus;
use super::error::WckError;

/// A module's load and position (the reply to a status read and a position move).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Status {
    /// Load, 0..=254 (the manual gives no unit; higher is more motor current).
    pub load: Load,
    /// Position, 0..=254 in steps of 1.055° (0..=268°).
    pub position: Position,
}

/// A module's reply in wheel mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct WheelStatus {
    /// Rotations counted since power-up, modulo 256 (the manual's "rotation count").
    pub rotations: u8,
    /// Position, 0..=254 in steps of 1.055°.
    pub position: Position,
}

/// Position-loop gains (dimensionless controller coefficients).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Gains {
    /// Proportional gain, 1..=254 (1..=120 recommended).
    pub p: PGain,
    /// Derivative gain, 0..=254.
    pub d: DGain,
}

/// Position-mode speed limit and acceleration range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SpeedAccel {
    /// Speed level 0..=30 (0 = no limit).
    pub speed: Speed,
    /// Acceleration range 20..=100.
    pub accel: Accel,
}

/// The external I/O port.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct IoState {
    /// The two digital outputs.
    pub outputs: IoBits,
    /// The A/D input, 0..=255 for 0..=5 V (19.6 mV a count).
    pub adc: u8,
}

/// A handle on one module (IDs 0..=30), borrowing its [`WckBus`].
///
/// Every method is one command of the manual's appendix A-1 (numbers in brackets), sent
/// with the retry policy of [`retry_class`](super::retry_class): reads and idempotent
/// commands are retried, EEPROM settings are verified by read-back, ID and baud changes
/// by talking to the module afterwards. Positions are in steps of 1.055° (0..=254) or
/// 0.325° (10-bit, 0..=1023).
#[derive(Debug)]
pub struct Servo<'a, L> {
    bus: &'a mut WckBus<L>,
    id: ServoId,
}

impl<L: ByteLink> WckBus<L> {
    /// A handle on the module with ID `id` (0..=30).
    pub const fn servo(&mut self, id: ServoId) -> Servo<'_, L> {
        Servo::new(self, id)
    }
}

impl<'a, L: ByteLink> Servo<'a, L> {
    pub(crate) const fn new(bus: &'a mut WckBus<L>, id: ServoId) -> Self {
        Self { bus, id }
    }

    /// The module's ID.
    pub const fn id(&self) -> ServoId {
        self.id
    }

    /// The bus this handle borrows.
    pub const fn bus(&mut self) -> &mut WckBus<L> {
        self.bus
    }

    fn exec(&mut self, command: &Command) -> Result<Reply, WckError> {
        match self.bus.execute(command)? {
            Some(reply) => Ok(reply),
            None => Err(self.bus.unexpected(command, None)),
        }
    }

    /// (1) Position move: go to `position` (0..=254, 1.055° a step) with `torque`
    /// (0 = maximum .. 4 = minimum). Returns the load and position *before* the move
    /// (from the attempt that got through, if the first reply was lost). The module
    /// stays within its [boundaries](Self::boundaries).
    pub fn move_to(&mut self, torque: TorqueLevel, position: Position) -> Result<Status, WckError> {
        let command = Command::Move {
            id: self.id,
            torque,
            position,
        };
        match self.exec(&command)? {
            Reply::Status { load, position } => Ok(Status { load, position }),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (3) Status read: load and position.
    pub fn status(&mut self) -> Result<Status, WckError> {
        let command = Command::StatusRead { id: self.id };
        match self.exec(&command)? {
            Reply::Status { load, position } => Ok(Status { load, position }),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (4) Passive: release the torque (the shaft turns freely and still reads).
    /// Returns the position (0..=254).
    pub fn passive(&mut self) -> Result<Position, WckError> {
        let command = Command::Passive { id: self.id };
        match self.exec(&command)? {
            Reply::Passive { position } => Ok(position),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (5) Wheel mode: turn continuously in `rotation` at `speed` (0 = stop, 1..=15).
    pub fn wheel(
        &mut self,
        rotation: Rotation,
        speed: WheelSpeed,
    ) -> Result<WheelStatus, WckError> {
        let command = Command::Wheel {
            id: self.id,
            rotation,
            speed,
        };
        match self.exec(&command)? {
            Reply::Wheel {
                rotations,
                position,
            } => Ok(WheelStatus {
                rotations,
                position,
            }),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (9) P, D gain read.
    pub fn gains(&mut self) -> Result<Gains, WckError> {
        let command = Command::GainRead { id: self.id };
        match self.exec(&command)? {
            Reply::Gains { p, d } => Ok(Gains { p, d }),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (8) P, D gain set, stored in EEPROM (about 121 ms) and verified by reading the
    /// gains back.
    pub fn set_gains(&mut self, gains: Gains) -> Result<(), WckError> {
        self.exec(&Command::GainSet {
            id: self.id,
            p: gains.p,
            d: gains.d,
        })
        .map(drop)
    }

    /// (12) Runtime P, D gain set: effective at once, lost at power-off. The reply echoes
    /// the gains.
    pub fn set_runtime_gains(&mut self, gains: Gains) -> Result<(), WckError> {
        self.exec(&Command::RuntimeGainSet {
            id: self.id,
            p: gains.p,
            d: gains.d,
        })
        .map(drop)
    }

    /// (11) I gain read.
    pub fn i_gain(&mut self) -> Result<IGain, WckError> {
        let command = Command::IGainRead { id: self.id };
        match self.exec(&command)? {
            Reply::IGain(i) => Ok(i),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (10) I gain set, stored in EEPROM and verified by read-back.
    pub fn set_i_gain(&mut self, i: IGain) -> Result<(), WckError> {
        self.exec(&Command::IGainSet { id: self.id, i }).map(drop)
    }

    /// (13) Runtime I gain set: effective at once, lost at power-off.
    pub fn set_runtime_i_gain(&mut self, i: IGain) -> Result<(), WckError> {
        self.exec(&Command::RuntimeIGainSet { id: self.id, i })
            .map(drop)
    }

    /// (16) Speed / acceleration read.
    pub fn speed(&mut self) -> Result<SpeedAccel, WckError> {
        let command = Command::SpeedRead { id: self.id };
        match self.exec(&command)? {
            Reply::SpeedAccel { speed, accel } => Ok(SpeedAccel { speed, accel }),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (15) Speed / acceleration set, stored in EEPROM and verified by read-back.
    pub fn set_speed(&mut self, value: SpeedAccel) -> Result<(), WckError> {
        self.exec(&Command::SpeedSet {
            id: self.id,
            speed: value.speed,
            accel: value.accel,
        })
        .map(drop)
    }

    /// (17) Runtime speed / acceleration set: effective at once, lost at power-off.
    /// The command has **no reply**: it is sent once and nothing confirms it arrived
    /// ([`Servo::speed`] reads what the module reports).
    pub fn set_runtime_speed(&mut self, value: SpeedAccel) -> Result<(), WckError> {
        self.bus
            .execute(&Command::RuntimeSpeedSet {
                id: self.id,
                speed: value.speed,
                accel: value.accel,
            })
            .map(drop)
    }

    /// (19) Over-load read: the threshold code (33..=199); [`Overload::milliamps`] gives
    /// it in mA (400..=1800 mA).
    pub fn overload(&mut self) -> Result<Overload, WckError> {
        let command = Command::OverloadRead { id: self.id };
        match self.exec(&command)? {
            Reply::Overload(o) => Ok(o),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (19) Over-load read, in mA (400..=1800).
    pub fn overload_milliamps(&mut self) -> Result<u16, WckError> {
        self.overload().map(Overload::milliamps)
    }

    /// (18) Over-load set, stored in EEPROM and verified by read-back. Above the
    /// threshold the module drops into passive mode by itself.
    pub fn set_overload(&mut self, overload: Overload) -> Result<(), WckError> {
        self.exec(&Command::OverloadSet {
            id: self.id,
            overload,
        })
        .map(drop)
    }

    /// (18) Over-load set in mA (400..=1800 mA, rounded to the nearest code). An
    /// out-of-range current is refused and nothing is sent.
    pub fn set_overload_milliamps(&mut self, milliamps: u16) -> Result<(), WckError> {
        let overload = Overload::from_milliamps(milliamps).map_err(|source| WckError::Value {
            command: "over-load set",
            source,
        })?;
        self.set_overload(overload)
    }

    /// (21) Boundary read: the positions (0..=254) the module may move between.
    pub fn boundaries(&mut self) -> Result<Boundaries, WckError> {
        let command = Command::BoundaryRead { id: self.id };
        match self.exec(&command)? {
            Reply::Boundaries(b) => Ok(b),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (20) Boundary set, stored in EEPROM and verified by read-back.
    pub fn set_boundaries(&mut self, bounds: Boundaries) -> Result<(), WckError> {
        self.exec(&Command::BoundarySet {
            id: self.id,
            bounds,
        })
        .map(drop)
    }

    /// (23) I/O read: the digital outputs and the A/D input (0..=255 for 0..=5 V).
    pub fn io(&mut self) -> Result<IoState, WckError> {
        let command = Command::IoRead { id: self.id };
        match self.exec(&command)? {
            Reply::Io { outputs, adc } => Ok(IoState { outputs, adc }),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (22) I/O write: set the two digital outputs. The reply echoes them.
    pub fn set_outputs(&mut self, outputs: IoBits) -> Result<(), WckError> {
        self.exec(&Command::IoWrite {
            id: self.id,
            outputs,
        })
        .map(drop)
    }

    /// (24) Motion data write: store a self-running program (up to 8 instructions; an
    /// empty program switches it off). The module restarts the program at once.
    ///
    /// Sent once, never resent (a resend would restart the program again), then verified
    /// by reading back the instruction count ((25) is all the module can report: a
    /// program of the same length is not told apart). If the write's reply was lost but
    /// the count reads back right, the upload counts as done.
    pub fn upload_program(&mut self, program: &Program) -> Result<(), WckError> {
        self.exec(&Command::MotionWrite {
            id: self.id,
            program: *program,
        })
        .map(drop)
    }

    /// (25) Motion data read: the number of instructions of the stored program (0..=8).
    pub fn program_count(&mut self) -> Result<MotionCount, WckError> {
        let command = Command::MotionRead { id: self.id };
        match self.exec(&command)? {
            Reply::MotionCount(n) => Ok(n),
            other => Err(self.bus.unexpected(&command, Some(other))),
        }
    }

    /// (26) 10-bit position move: go to `position` (0..=1023, 0.325° a step) with
    /// `torque` (0..=254 per the manual). Returns the 10-bit position *before* the move.
    pub fn move10(
        &mut self,
        torque: DataByte,
        position: Position10,
    ) -> Result<Position10, WckError> {
        self.bus.move10(ExtServoId::from(self.id), torque, position)
    }

    /// (27) 10-bit position read: 0..=1023, 0.325° a step.
    pub fn read10(&mut self) -> Result<Position10, WckError> {
        self.bus.read10(ExtServoId::from(self.id))
    }

    /// (14) ID set: renames the module to `new_id` (0..=253; IDs above 30 are reachable
    /// only through the 10-bit commands, [`WckBus::move10`] and [`WckBus::read10`]).
    ///
    /// Refused with [`WckError::IdInUse`] if a module already answers at `new_id`. Sent
    /// once (never resent), then verified by reading the module at its new ID: if that
    /// fails and it still answers at the old ID the error is
    /// [`WckError::NotApplied`], if it answers at neither [`WckError::NotVerified`].
    /// On success this handle is moved to the new ID when it is 0..=30.
    pub fn set_id(&mut self, new_id: ExtServoId) -> Result<(), WckError> {
        self.bus.set_id(self.id, new_id)?;
        if let Ok(id) = ServoId::new(new_id.get()) {
            self.id = id;
        }
        Ok(())
    }

    /// (7) Baud rate set: the module switches to `baud` after its reply (sent at the old
    /// rate). Sent once (never resent); then the bus switches its link to `baud` and
    /// verifies by reading the module's status there. If that fails the bus switches back
    /// and reads at the old rate: [`WckError::NotApplied`] if the module still answers
    /// there, [`WckError::NotVerified`] if at neither (the bus stays at the old rate).
    ///
    /// Every other module on the bus stays at the old rate: change them all, or move the
    /// bus back with [`WckBus::set_host_baud`].
    pub fn set_baud(&mut self, baud: BaudRate) -> Result<(), WckError> {
        self.bus.set_module_baud(self.id, baud)
    }
}
