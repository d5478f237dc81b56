//! A joint's answers to frames: requests dispatched, malformed frames, servo feedback,
//! status and the broadcast protocol.

use super::{
    ActualSpeed, BroadcastCurrent, BroadcastFeedback, BroadcastPosition, BroadcastReadReply,
    BroadcastRegister, BroadcastRegisterReply, CanFrame, CmdError, Current, Duration, ErrorCode,
    Feature, FeedForward, Guard, JointId, JointStatus, Malformed, MalformedReason, Phase, Position,
    RegisterAddr, RegisterOp, RegisterSlot, ReplyMask, Request, Sample, ServoFeedback, SimJoint,
    Temperature, Voltage, WireReply, Words, WriteData, WriteOutcome, WriteStatus, gaussian, reg,
    registers, round_i64, rpm_to_rad_s, saturate_i16, saturate_i32, status,
};

impl SimJoint {
    pub(super) fn malformed(
        &mut self,
        frame: &CanFrame,
        bad: &Malformed,
        me: JointId,
        now: Duration,
    ) -> Option<WireReply> {
        if self.phase != Phase::Application {
            return None;
        }
        let raw = frame.standard_raw_id()?;
        let data = frame.data();
        match bad.reason {
            // Option: frames to node 0 apply their writes silently (C32).
            MalformedReason::InterfaceBoard if self.cfg.apply_id0_writes && raw == 0x000 => {
                let as_mine =
                    CanFrame::new_fd(CanFrame::standard_id(u16::from(me.get())).ok()?, data)
                        .ok()?;
                if let Ok(Request::Write { addr, data, .. }) = Request::decode(&as_mine) {
                    let (words, n) = data.words();
                    let _ = self.write_words(addr.get(), words.get(..n)?, now);
                }
                return None;
            }
            // Option: GRIP's command 0x03 = write without reply.
            MalformedReason::UnknownCommand { cmd: 3 }
                if self.cfg.silent_write_cmd3 && bad.joint == Some(me) =>
            {
                let (&index, rest) = data.get(1..)?.split_first()?;
                let write = WriteData::from_bytes(rest)?;
                let (words, n) = write.words();
                let _ = self.write_words(index, words.get(..n)?, now);
                return None;
            }
            // Option: any even number of data bytes writes that many registers.
            MalformedReason::WriteLength { data_len }
                if self.cfg.any_even_write_length && bad.joint == Some(me) && data_len % 2 == 0 =>
            {
                let index = *data.get(1)?;
                let words: Vec<u16> = data
                    .get(2..)?
                    .chunks_exact(2)
                    .map(|c| u16::from_le_bytes([c[0], c[1]]))
                    .collect();
                let addr = RegisterAddr::new(index).ok()?;
                let status = match self.write_words(index, &words, now) {
                    WriteOutcome::Ack(ok) => status(ok),
                    WriteOutcome::Permission => {
                        return Some(WireReply::CmdErr {
                            joint: me,
                            code: self.cfg.cmd_err_code,
                            error: CmdError::Permission,
                        });
                    }
                };
                return Some(WireReply::WriteAck {
                    joint: me,
                    addr,
                    status,
                });
            }
            _ => {}
        }
        let (joint, error) = bad.response()?;
        (joint == me).then_some(WireReply::CmdErr {
            joint: me,
            code: self.cfg.cmd_err_code,
            error,
        })
    }

    pub(super) fn dispatch(
        &mut self,
        req: Request,
        me: JointId,
        now: Duration,
    ) -> Option<WireReply> {
        if let Phase::Bootloader { .. } = self.phase {
            // The bootloader answers only writes to IAP_FLAG (§6.1).
            return match req {
                Request::Write { joint, addr, data } if joint == me && addr == reg::IAP_FLAG => {
                    let (words, _) = data.words();
                    if words[0] == 0 {
                        self.start_application();
                    }
                    Some(WireReply::WriteAck {
                        joint: me,
                        addr,
                        status: WriteStatus::Ok,
                    })
                }
                _ => None,
            };
        }
        match req {
            Request::Read { joint, range } if joint == me => {
                let mut words = [0u16; registers::MAX_READ_COUNT as usize];
                let out = words.get_mut(..usize::from(range.count()))?;
                self.read_words(range.start().get(), out);
                WireReply::read(me, range, out).ok()
            }
            Request::Write { joint, addr, data } if joint == me => {
                let (words, n) = data.words();
                match self.write_words(addr.get(), words.get(..n)?, now) {
                    WriteOutcome::Ack(ok) => Some(WireReply::WriteAck {
                        joint: me,
                        addr,
                        status: status(ok),
                    }),
                    WriteOutcome::Permission => Some(WireReply::CmdErr {
                        joint: me,
                        code: self.cfg.cmd_err_code,
                        error: CmdError::Permission,
                    }),
                }
            }
            Request::PositionServo { joint, target } if joint == me => {
                let feedback = self.servo_feedback();
                self.set_position_target(target.0, false);
                if self.cfg.watchdog.guard_point_to_point {
                    self.arm_watchdog(now, Guard::Position, true);
                }
                Some(WireReply::ServoFeedback {
                    joint: me,
                    feedback,
                })
            }
            Request::SpeedServo { joint, target } if joint == me => {
                let feedback = self.servo_feedback();
                self.set_i32(reg::TAG_SPEED, target.0);
                Some(WireReply::ServoFeedback {
                    joint: me,
                    feedback,
                })
            }
            Request::CurrentServo { joint, target } if joint == me => {
                let feedback = self.servo_feedback();
                self.set_i32(reg::TAG_CURRENT, target.0);
                Some(WireReply::ServoFeedback {
                    joint: me,
                    feedback,
                })
            }
            Request::StatusQuery { joint } if joint == me => Some(WireReply::Status {
                joint: me,
                status: self.status(),
            }),
            // Firmware older than the broadcast gate (D5.XX / E2.XX) ignores broadcast frames.
            Request::BroadcastPosition(_)
            | Request::BroadcastCurrent(_)
            | Request::BroadcastRegister(_)
            | Request::BroadcastStatus(_)
                if !self.has_feature(Feature::Broadcast) =>
            {
                None
            }
            Request::BroadcastPosition(b) => self.broadcast_position(&b, me, now),
            Request::BroadcastCurrent(b) => self.broadcast_current(&b, me, now),
            Request::BroadcastRegister(b) => self.broadcast_register(&b, me, now),
            Request::BroadcastStatus(b) => {
                self.counter = self.counter.wrapping_add(1);
                self.broadcast_feedback(b.mask, me)
            }
            _ => None,
        }
    }

    pub(super) fn servo_feedback(&mut self) -> ServoFeedback {
        let s = self.sample();
        ServoFeedback {
            current: Current(s.current),
            speed: ActualSpeed(s.speed),
            position: Position(s.position),
            enable: u16::from(s.enabled),
            error: ErrorCode(s.error),
        }
    }

    pub(super) fn status(&mut self) -> JointStatus {
        let s = self.sample();
        JointStatus {
            error: ErrorCode(s.error),
            voltage: Voltage(s.voltage),
            temperature: Temperature(s.temperature),
            enable: u8::from(s.enabled),
            brake: u8::from(s.brake_locked),
            position: Position(s.position),
            current: self.cfg.status_len_16.then_some(Current(s.current)),
        }
    }

    /// Slot index of this joint in broadcast frames (IDs 1..=7).
    pub(super) fn slot(me: JointId) -> Option<usize> {
        me.has_broadcast_slot().then(|| usize::from(me.get() - 1))
    }

    pub(super) fn broadcast_feedback(&mut self, mask: ReplyMask, me: JointId) -> Option<WireReply> {
        if !mask.selects(me) {
            return None;
        }
        let s = self.sample();
        let feedback = BroadcastFeedback {
            current: Current(s.current),
            speed: ActualSpeed(s.speed),
            position: Position(s.position),
            error: ErrorCode(s.error),
            voltage: Voltage(s.voltage),
            temperature: Temperature(s.temperature),
            state: u8::from(s.enabled) | (u8::from(s.brake_locked) << 7),
            encoder: 0,
            counter: s.broadcast_counter,
        };
        Some(WireReply::BroadcastFeedback {
            joint: me,
            feedback,
        })
    }

    pub(super) fn arm_watchdog(&mut self, now: Duration, guard: Guard, with_data: bool) {
        let mode_ok = match guard {
            Guard::Position => self.ram[reg::TAG_WORK_MODE.index()] == 3,
            Guard::Current => self.ram[reg::TAG_WORK_MODE.index()] == 1,
        };
        let armed = self.watchdog.is_some_and(|(_, g)| g == guard);
        if self.enabled
            && mode_ok
            && (with_data || (armed && !self.cfg.watchdog.rearm_only_with_data))
        {
            self.watchdog = Some((now + self.cfg.watchdog.timeout, guard));
        }
    }

    pub(super) fn broadcast_position(
        &mut self,
        b: &BroadcastPosition,
        me: JointId,
        now: Duration,
    ) -> Option<WireReply> {
        self.counter = self.counter.wrapping_add(1);
        let slot = Self::slot(me)?;
        // The feedback shows the state before the new target (as point-to-point).
        let reply = self.broadcast_feedback(b.mask, me);
        let data = b.slots.get(slot).copied().flatten();
        if let Some(slot) = data {
            let layout = self.cfg.feed_forward_layout;
            self.speed_ff = if b.feed_forward.speed(layout) == FeedForward::Host {
                rpm_to_rad_s(
                    f64::from(slot.speed_ff) * robobus_whj::units::TARGET_SPEED_RPM_PER_COUNT,
                )
            } else {
                0.0
            };
            self.current_ff = if b.feed_forward.current(layout) == FeedForward::Host {
                f64::from(slot.current_ff) * f64::from(robobus_whj::units::CURRENT_FF_MA_PER_COUNT)
                    / 1000.0
            } else {
                0.0
            };
            self.set_position_target(slot.position.0, false);
        }
        self.arm_watchdog(now, Guard::Position, data.is_some());
        reply
    }

    pub(super) fn broadcast_current(
        &mut self,
        b: &BroadcastCurrent,
        me: JointId,
        now: Duration,
    ) -> Option<WireReply> {
        self.counter = self.counter.wrapping_add(1);
        let slot = Self::slot(me)?;
        let reply = self.broadcast_feedback(b.mask, me);
        let data = b.slots.get(slot).copied().flatten();
        if let Some(current) = data {
            self.set_i32(reg::TAG_CURRENT, current.0);
        }
        if self.cfg.watchdog.guard_broadcast_current {
            self.arm_watchdog(now, Guard::Current, data.is_some());
        }
        reply
    }

    pub(super) fn broadcast_register(
        &mut self,
        b: &BroadcastRegister,
        me: JointId,
        now: Duration,
    ) -> Option<WireReply> {
        self.counter = self.counter.wrapping_add(1);
        let slot = Self::slot(me)?;
        // An unselected joint still executes its slot but stays silent (§8.1, 8.12 (8)).
        let reply = match b.slots.get(slot).copied()? {
            RegisterSlot::Empty | RegisterSlot::Invalid(_) => return None,
            RegisterSlot::Op(RegisterOp::Read(range)) => {
                let mut words = [0u16; registers::MAX_READ_COUNT as usize];
                let out = words.get_mut(..usize::from(range.count()))?;
                self.read_words(range.start().get(), out);
                let length_prefix = match self.cfg.broadcast_read_reply {
                    BroadcastReadReply::Doc => None,
                    BroadcastReadReply::LengthPrefixed => u8::try_from(2 + 2 * out.len()).ok(),
                };
                BroadcastRegisterReply::Read {
                    addr: range.start(),
                    words: Words::from_slice(out).ok()?,
                    length_prefix,
                }
            }
            RegisterSlot::Op(RegisterOp::Write { addr, data }) => {
                let (words, n) = data.words();
                let ok =
                    self.write_words(addr.get(), words.get(..n)?, now) == WriteOutcome::Ack(true);
                BroadcastRegisterReply::WriteAck {
                    addr,
                    status: status(ok),
                }
            }
        };
        b.mask
            .selects(me)
            .then_some(WireReply::BroadcastRegister { joint: me, reply })
    }

    // ----- register access --------------------------------------------------------------

    /// Measured values with noise, sampled once per frame.
    pub(super) fn sample(&mut self) -> Sample {
        let mut s = self.sample_exact();
        if self.cfg.current_noise_ma > 0.0 {
            let noise = gaussian(&mut self.rng) * self.cfg.current_noise_ma / self.ma_per_count();
            s.current = saturate_i32(i64::from(s.current) + round_i64(noise));
        }
        s
    }

    pub(super) fn sample_exact(&self) -> Sample {
        let current = self.mech.current * 1000.0 / self.ma_per_count();
        let rpm = self.mech.omega * 60.0 / core::f64::consts::TAU;
        Sample {
            current: saturate_i32(round_i64(current)),
            speed: saturate_i32(round_i64(
                rpm / robobus_whj::units::ACTUAL_SPEED_RPM_PER_COUNT,
            )),
            position: self.reported_position(),
            enabled: self.enabled,
            error: self.errors,
            voltage: saturate_i16(round_i64(self.mech.bus_v * 100.0)),
            temperature: saturate_i16(round_i64(self.mech.temp_c * 10.0)),
            brake_locked: self.brake_locked(),
            broadcast_counter: self.counter,
        }
    }
}
