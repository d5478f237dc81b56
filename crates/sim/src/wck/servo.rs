//! One simulated wCK module: the firmware as a state machine over typed commands, on top
//! of [`Mechanics`].

use core::time::Duration;

use robobus_wck::program::{FALSE_CONDITION, FalseCondition, Instruction, MotionType, Repeat};
use robobus_wck::timing;
use robobus_wck::{
    BaudRate, Command, ExtServoId, IoBits, Load, Position, Position10, Reply, Rotation, ServoId,
};

use super::mechanics::{
    DEG_PER_STEP8, DEG_PER_STEP10, Drive, Mechanics, TICK_NANOS, TickEvent, Tuning,
};
use super::model::Model;
use super::params::{Eeprom, Runtime};

/// Mechanics tick as a [`Duration`].
pub const TICK: Duration = Duration::from_nanos(TICK_NANOS);

/// Turnaround and power-up timing of a module (section 2-3, the wire-timing notes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Timing {
    /// From the end of a command to the start of its reply, for operation, read and
    /// runtime commands. Default 1006.6 µs (the wire-timing notes: the manual's 1180 µs at
    /// 115200 and 1354 µs at 57600 minus the reply's wire time).
    pub turnaround: Duration,
    /// The same for commands that write EEPROM; the module ignores the bus meanwhile.
    /// Default 121 ms ([`timing::T_EEPROM`]).
    pub eeprom_write: Duration,
    /// After power-up the module ignores the bus this long (section 2-3: 65 ms).
    pub power_up_deaf: Duration,
}

impl Timing {
    /// The module as the manual describes it.
    pub const MANUAL: Self = Self {
        turnaround: timing::T_PROC,
        eeprom_write: timing::T_EEPROM,
        power_up_deaf: timing::POWER_UP_DEAF,
    };

    /// No processing time at all: replies start the instant a command ends, EEPROM writes
    /// are instant and there is no deaf time after power-up (benchmarks of the wire alone).
    pub const ZERO: Self = Self {
        turnaround: Duration::ZERO,
        eeprom_write: Duration::ZERO,
        power_up_deaf: Duration::ZERO,
    };
}

impl Default for Timing {
    fn default() -> Self {
        Self::MANUAL
    }
}

/// What the motor is doing, as a host would name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Position control.
    Position,
    /// Torque released (also after an over-load and at power-up).
    Passive,
    /// Break mode (dynamic brake).
    Break,
    /// Wheel mode.
    Wheel,
    /// No power.
    Off,
}

/// A reply the module will send.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Answer {
    /// The two reply bytes.
    pub bytes: [u8; 2],
    /// Processing time from the end of the command to the first bit of the reply.
    pub delay: Duration,
}

/// What the module does with a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Outcome {
    /// The reply, if the command has one and addressed this module.
    pub answer: Option<Answer>,
    /// How long after the end of the command the module ignores the bus (the EEPROM write
    /// window, or the turnaround plus the reply).
    pub busy: Duration,
    /// The baud rate the module switches to once its reply is out.
    pub new_baud: Option<BaudRate>,
}

impl Outcome {
    const IGNORED: Self = Self {
        answer: None,
        busy: Duration::ZERO,
        new_baud: None,
    };
}

/// The self-running program interpreter's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct ProgramState {
    running: bool,
    pc: usize,
    passes_done: u16,
    wait_until: Duration,
}

/// One simulated wCK module.
///
/// Behaviour decided where the manual is silent (each also in the crate docs):
/// * Reads return the values in effect (the runtime copies after a runtime set).
/// * At power-up the motor is passive until a command (or the motion program) drives it.
/// * A baud rate set is answered at the old rate; the new rate applies after the reply.
/// * Position commands are limited to the boundaries: `target = min(max(target, lower),
///   upper)`; a 10-bit move is limited to the same angles. Wheel mode ignores them.
/// * A 10-bit move's torque byte (0..=254) uses torque level `min(torque, 4)`.
/// * Motion program: instructions take no time except delays; a position instruction
///   starts the move and goes on (like the position command); a false condition skips the
///   next instruction ([`FALSE_CONDITION`]); `repeat n` makes the whole program run n times
///   (`repeat forever` or no repeat instruction: forever); `end` stops it. It starts at
///   power-up and whenever a program with at least one instruction is written; a pass
///   without a delay takes at least one control tick (0.5 ms).
#[derive(Debug, Clone)]
pub struct Servo {
    model: Model,
    eeprom: Eeprom,
    runtime: Runtime,
    timing: Timing,
    mech: Mechanics,
    powered: bool,
    power_on_at: Duration,
    /// Time up to which the mechanics have been advanced (a multiple of [`TICK`]).
    t: Duration,
    outputs: IoBits,
    adc: u8,
    overloads: u32,
    program: ProgramState,
}

impl Servo {
    /// A module of `model` with `eeprom`, its shaft at `angle` degrees, powered on at
    /// `now`.
    pub fn new(model: Model, eeprom: Eeprom, angle: f64, timing: Timing, now: Duration) -> Self {
        let mut s = Self {
            model,
            eeprom,
            runtime: Runtime::from_eeprom(&eeprom),
            timing,
            mech: Mechanics::new(model, angle),
            powered: false,
            power_on_at: now,
            t: floor_tick(now),
            outputs: IoBits::MIN,
            adc: 0,
            overloads: 0,
            program: ProgramState::default(),
        };
        s.power_on(now);
        s
    }

    /// The model.
    pub const fn model(&self) -> Model {
        self.model
    }

    /// The EEPROM contents.
    pub const fn eeprom(&self) -> &Eeprom {
        &self.eeprom
    }

    /// The values in effect.
    pub const fn runtime(&self) -> &Runtime {
        &self.runtime
    }

    /// The module's ID.
    pub const fn id(&self) -> ExtServoId {
        self.eeprom.id
    }

    /// The module's baud rate.
    pub const fn baud(&self) -> BaudRate {
        self.eeprom.baud
    }

    /// The timing in use.
    pub const fn timing(&self) -> Timing {
        self.timing
    }

    /// Whether the module is powered.
    pub const fn is_powered(&self) -> bool {
        self.powered
    }

    /// Whether the module listens to the bus at `now` (powered and past the 65 ms after
    /// power-up).
    pub fn listens_at(&self, now: Duration) -> bool {
        self.powered && now >= self.power_on_at + self.timing.power_up_deaf
    }

    /// The mechanics (angle, speed, current, ...).
    pub const fn mechanics(&self) -> &Mechanics {
        &self.mech
    }

    /// The current mode.
    pub const fn mode(&self) -> Mode {
        if !self.powered {
            return Mode::Off;
        }
        match self.mech.drive() {
            Drive::Position { .. } => Mode::Position,
            Drive::Passive => Mode::Passive,
            Drive::Brake => Mode::Break,
            Drive::Wheel { .. } => Mode::Wheel,
        }
    }

    /// Shaft angle in degrees.
    pub const fn angle(&self) -> f64 {
        self.mech.angle()
    }

    /// Standard-resolution position reading 0..=254.
    pub fn position(&self) -> u8 {
        self.mech.position8()
    }

    /// High-resolution position reading 0..=1023.
    pub fn position10(&self) -> u16 {
        self.mech.position10()
    }

    /// The load byte the module would report now.
    pub fn load(&self) -> u8 {
        self.mech.load()
    }

    /// Full rotations counted since power-up (counter-clockwise positive).
    pub const fn rotations(&self) -> i64 {
        self.mech.rotations()
    }

    /// The digital outputs.
    pub const fn outputs(&self) -> IoBits {
        self.outputs
    }

    /// How many times the module dropped into passive mode from over-load.
    pub const fn overload_trips(&self) -> u32 {
        self.overloads
    }

    /// Whether the self-running program is running.
    pub const fn program_running(&self) -> bool {
        self.program.running
    }

    // ----- test API: the outside world -----

    /// Sets the A/D input (0..=255 for 0..=5 V).
    pub fn set_adc(&mut self, value: u8) {
        self.adc = value;
    }

    /// Applies a constant external torque in kg·cm (positive towards larger angles): a
    /// load, a push, gravity. 0 (or a non-finite value) removes it.
    pub fn push(&mut self, torque_kgcm: f64) {
        self.mech.external.torque = if torque_kgcm.is_finite() {
            torque_kgcm
        } else {
            0.0
        };
    }

    /// Holds the shaft still (or lets go).
    pub fn hold(&mut self, held: bool) {
        self.mech.external.held = held;
    }

    /// Turns the shaft to `degrees` by hand, at once.
    pub fn set_angle(&mut self, degrees: f64) {
        self.mech.set_angle(degrees);
    }

    /// Turns the shaft by hand to a standard-resolution position.
    pub fn set_position(&mut self, position: u8) {
        self.mech.set_angle(f64::from(position) * DEG_PER_STEP8);
    }

    /// Replaces the EEPROM contents (as if written by a programmer). The ID applies at
    /// once; everything else at the next power-up (`Bus::power_cycle`), which is also when
    /// the bus starts listening at a new baud rate.
    pub fn set_eeprom(&mut self, eeprom: Eeprom) {
        self.eeprom = eeprom;
    }

    // ----- power -----

    /// Switches the power off at `now`: everything but the EEPROM is lost.
    pub fn power_off(&mut self, now: Duration) {
        self.advance(now);
        self.powered = false;
        self.mech.power_off();
        self.program.running = false;
    }

    /// Switches the power on at `now`: runtime values from EEPROM, outputs off, rotation
    /// count 0, motor passive, deaf for [`Timing::power_up_deaf`], motion program started
    /// if there is one.
    pub fn power_on(&mut self, now: Duration) {
        self.advance(now);
        self.powered = true;
        self.power_on_at = now;
        self.runtime = Runtime::from_eeprom(&self.eeprom);
        self.outputs = IoBits::MIN;
        self.mech.reset_rotations();
        self.mech.set_drive(Drive::Passive);
        self.start_program(now);
    }

    // ----- time -----

    /// Advances mechanics and the motion program to `now` (in [`TICK`] steps).
    pub fn advance(&mut self, now: Duration) {
        while self.t + TICK <= now {
            self.t += TICK;
            if self.powered {
                self.run_program();
            }
            let tuning = self.tuning();
            if self.mech.tick(&tuning) == TickEvent::Overload {
                self.overloads += 1;
            }
        }
    }

    fn tuning(&self) -> Tuning {
        Tuning {
            p: self.runtime.p.get(),
            d: self.runtime.d.get(),
            i: self.runtime.i.get(),
            speed: self.runtime.speed.get(),
            accel: self.runtime.accel.get(),
            overload_ma: self.eeprom.overload.milliamps(),
        }
    }

    // ----- commands -----

    /// Acts on a command that ended at `now` (the module is assumed to listen; see
    /// [`Servo::listens_at`]). Commands for other modules are ignored.
    pub fn handle(&mut self, cmd: &Command, now: Duration) -> Outcome {
        self.advance(now);
        if !self.powered || !cmd.target().includes(self.eeprom.id) {
            return Outcome::IGNORED;
        }
        let reply = self.execute(cmd);
        let new_baud = match cmd {
            Command::BaudSet { baud, .. } => Some(*baud),
            _ => None,
        };
        let delay = if cmd.writes_eeprom() {
            self.timing.eeprom_write
        } else {
            self.timing.turnaround
        };
        let answer = reply.map(|bytes| Answer { bytes, delay });
        let busy = if answer.is_some() || cmd.writes_eeprom() {
            delay
        } else {
            Duration::ZERO
        };
        Outcome {
            answer,
            busy,
            new_baud,
        }
    }

    fn status(&self) -> [u8; 2] {
        let load = Load::new(self.load()).unwrap_or(Load::MAX);
        Reply::Status {
            load,
            position: self.pos8(),
        }
        .to_bytes()
    }

    fn pos8(&self) -> Position {
        Position::new(self.position()).unwrap_or(Position::MAX)
    }

    fn move_to(&mut self, position: u8, level: u8) {
        let b = self.eeprom.bounds;
        let p = position.max(b.lower().get()).min(b.upper().get());
        self.mech.set_drive(Drive::Position {
            target: f64::from(p) * DEG_PER_STEP8,
            level,
        });
    }

    fn move10_to(&mut self, position: u16, level: u8) {
        let b = self.eeprom.bounds;
        let lo = f64::from(b.lower().get()) * DEG_PER_STEP8;
        let hi = f64::from(b.upper().get()) * DEG_PER_STEP8;
        let target = (f64::from(position) * DEG_PER_STEP10).max(lo).min(hi);
        self.mech.set_drive(Drive::Position { target, level });
    }

    /// Applies a command addressed to this module; returns the reply bytes if it has one.
    #[allow(clippy::too_many_lines)] // one arm per command of A-1
    fn execute(&mut self, cmd: &Command) -> Option<[u8; 2]> {
        let reply = match *cmd {
            Command::Move {
                torque, position, ..
            } => {
                let bytes = self.status();
                self.move_to(position.get(), torque.get());
                return Some(bytes);
            }
            Command::SyncMove(sync) => {
                let mine = ServoId::new(self.eeprom.id.get())
                    .ok()
                    .and_then(|id| sync.position_of(id));
                if let Some(p) = mine {
                    self.move_to(p.get(), sync.torque().get());
                }
                return None;
            }
            Command::StatusRead { .. } => return Some(self.status()),
            Command::Passive { .. } => {
                self.mech.set_drive(Drive::Passive);
                Reply::Passive {
                    position: self.pos8(),
                }
            }
            Command::Wheel {
                rotation, speed, ..
            } => {
                self.mech.set_drive(Drive::Wheel {
                    ccw: rotation == Rotation::Ccw,
                    speed: speed.get(),
                });
                // Rotation count as a byte: wraps, clockwise turns count down.
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let rotations = self.mech.rotations().rem_euclid(256) as u8;
                Reply::Wheel {
                    rotations,
                    position: self.pos8(),
                }
            }
            Command::Break => {
                self.mech.set_drive(Drive::Brake);
                return Some([self.eeprom.id.get(), self.position()]);
            }
            Command::BaudSet { baud, .. } => {
                self.eeprom.baud = baud;
                Reply::Baud(baud)
            }
            Command::GainSet { p, d, .. } => {
                (self.eeprom.p, self.eeprom.d, self.runtime.p, self.runtime.d) = (p, d, p, d);
                Reply::Gains { p, d }
            }
            Command::GainRead { .. } => Reply::Gains {
                p: self.runtime.p,
                d: self.runtime.d,
            },
            Command::RuntimeGainSet { p, d, .. } => {
                (self.runtime.p, self.runtime.d) = (p, d);
                Reply::Gains { p, d }
            }
            Command::IGainSet { i, .. } => {
                (self.eeprom.i, self.runtime.i) = (i, i);
                Reply::IGain(i)
            }
            Command::IGainRead { .. } => Reply::IGain(self.runtime.i),
            Command::RuntimeIGainSet { i, .. } => {
                self.runtime.i = i;
                Reply::IGain(i)
            }
            Command::IdSet { new_id, .. } => {
                self.eeprom.id = new_id;
                Reply::Id(new_id)
            }
            Command::SpeedSet { speed, accel, .. } => {
                (
                    self.eeprom.speed,
                    self.eeprom.accel,
                    self.runtime.speed,
                    self.runtime.accel,
                ) = (speed, accel, speed, accel);
                Reply::SpeedAccel { speed, accel }
            }
            Command::SpeedRead { .. } => Reply::SpeedAccel {
                speed: self.runtime.speed,
                accel: self.runtime.accel,
            },
            Command::RuntimeSpeedSet { speed, accel, .. } => {
                (self.runtime.speed, self.runtime.accel) = (speed, accel);
                return None;
            }
            Command::OverloadSet { overload, .. } => {
                self.eeprom.overload = overload;
                Reply::Overload(overload)
            }
            Command::OverloadRead { .. } => Reply::Overload(self.eeprom.overload),
            Command::BoundarySet { bounds, .. } => {
                self.eeprom.bounds = bounds;
                Reply::Boundaries(bounds)
            }
            Command::BoundaryRead { .. } => Reply::Boundaries(self.eeprom.bounds),
            Command::IoWrite { outputs, .. } => {
                self.outputs = outputs;
                Reply::Outputs(outputs)
            }
            Command::IoRead { .. } => Reply::Io {
                outputs: self.outputs,
                adc: self.adc,
            },
            Command::MotionWrite { program, .. } => {
                self.eeprom.program = program;
                let count = program.count();
                let now = self.t;
                self.start_program(now);
                Reply::MotionCount(count)
            }
            Command::MotionRead { .. } => Reply::MotionCount(self.eeprom.program.count()),
            Command::Move10 {
                torque, position, ..
            } => {
                let now = Position10::new(self.position10()).unwrap_or(Position10::MAX);
                self.move10_to(position.get(), torque.get().min(4));
                Reply::Position10(now)
            }
            Command::Read10 { .. } => {
                Reply::Position10(Position10::new(self.position10()).unwrap_or(Position10::MAX))
            }
        };
        Some(reply.to_bytes())
    }

    // ----- self-running motion program -----

    fn start_program(&mut self, now: Duration) {
        self.program = ProgramState {
            running: self.powered && !self.eeprom.program.is_empty(),
            pc: 0,
            passes_done: 0,
            wait_until: now,
        };
    }

    /// Runs instructions until a delay, the end of a pass, or the end of the program.
    fn run_program(&mut self) {
        if !self.program.running || self.t < self.program.wait_until {
            return;
        }
        let program = self.eeprom.program;
        let instructions = program.instructions();
        // At most one pass per tick.
        for _ in 0..=instructions.len() {
            let Some(&ins) = instructions.get(self.program.pc) else {
                // End of a pass.
                self.program.passes_done = self.program.passes_done.saturating_add(1);
                self.program.pc = 0;
                if let Some(n) = repeat_count(instructions)
                    && self.program.passes_done >= u16::from(n)
                {
                    self.program.running = false;
                }
                return;
            };
            self.program.pc += 1;
            match ins {
                Instruction::None | Instruction::Repeat(_) => {}
                Instruction::Move { torque, position } => {
                    self.move_to(position.get(), torque.get());
                }
                Instruction::Motion(MotionType::Passive) => self.mech.set_drive(Drive::Passive),
                Instruction::Motion(MotionType::Break) => self.mech.set_drive(Drive::Brake),
                Instruction::Motion(MotionType::Wheel(rotation, speed)) => {
                    self.mech.set_drive(Drive::Wheel {
                        ccw: rotation == Rotation::Ccw,
                        speed: speed.get(),
                    });
                }
                Instruction::Delay(ms) => {
                    self.program.wait_until = self.t + ms.duration();
                    return;
                }
                Instruction::Output(bits) => self.outputs = bits,
                Instruction::IfPosition(op, value) => {
                    let holds = op.holds(self.position(), value.get());
                    if !self.condition(holds) {
                        return;
                    }
                }
                Instruction::IfAdc(op, value) => {
                    let holds = op.holds(self.adc, value.get());
                    if !self.condition(holds) {
                        return;
                    }
                }
                Instruction::End => {
                    self.program.running = false;
                    return;
                }
            }
        }
    }

    /// Applies a condition's result; returns whether to keep executing this tick.
    fn condition(&mut self, holds: bool) -> bool {
        if holds {
            return true;
        }
        match FALSE_CONDITION {
            FalseCondition::SkipNext => {
                self.program.pc += 1;
                true
            }
            FalseCondition::WaitUntilTrue => {
                self.program.pc -= 1;
                false
            }
        }
    }
}

/// The repetition count of a program: `Some(n)` for `repeat n`, `None` for forever.
fn repeat_count(instructions: &[Instruction]) -> Option<u8> {
    instructions.iter().find_map(|i| match i {
        Instruction::Repeat(Repeat::Times(n)) => Some(n.get()),
        _ => None,
    })
}

/// `t` rounded down to a multiple of [`TICK`].
fn floor_tick(t: Duration) -> Duration {
    let tick = TICK.as_nanos();
    let n = t.as_nanos() / tick * tick;
    Duration::from_nanos(u64::try_from(n).unwrap_or(u64::MAX))
}
