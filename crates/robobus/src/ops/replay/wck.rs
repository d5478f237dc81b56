//! wCK packets of a hex log: commands decoded as a module decodes them, replies against their command.

use std::collections::VecDeque;

use robobus_wck::{Command, DecodeError, StreamDecoder, Target};

use super::{Direction, Entry, EntryKind, Field};

/// Bytes kept at most in one noise or unexpected entry before it is emitted.
const MAX_RUN: usize = 256;

/// A command waiting for its reply.
#[derive(Debug)]
struct Waiting {
    command: Command,
    line: u64,
    time: String,
    /// Reply bytes so far, and the line and time of the first.
    bytes: Vec<u8>,
    first: Option<(u64, String)>,
}

/// A run of bytes being collected (noise, unexpected reply bytes).
#[derive(Debug, Default)]
struct Run {
    bytes: Vec<u8>,
    start: Option<(u64, String)>,
}

impl Run {
    fn push(&mut self, line: u64, time: &str, byte: u8) {
        if self.start.is_none() {
            self.start = Some((line, time.to_owned()));
        }
        self.bytes.push(byte);
    }

    fn take(&mut self) -> Option<(u64, String, Vec<u8>)> {
        let (line, time) = self.start.take()?;
        Some((line, time, std::mem::take(&mut self.bytes)))
    }
}

#[derive(Debug, Default)]
pub(super) struct WckState {
    decoder: StreamDecoder,
    /// Bytes of the packet in progress.
    packet: Vec<u8>,
    packet_start: Option<(u64, String)>,
    noise: Run,
    unexpected: Run,
    waiting: Option<Waiting>,
}

fn servo_of(command: &Command) -> Option<u8> {
    match command.target() {
        Target::Servo(id) => Some(id.get()),
        Target::Extended(id) => Some(id.get()),
        Target::Broadcast => None,
    }
}

impl WckState {
    fn flush_noise(&mut self, out: &mut VecDeque<Entry>) {
        if let Some((line, time, bytes)) = self.noise.take() {
            let n = bytes.len();
            out.push_back(
                Entry::new(line, Some(time), Direction::ToDevice, EntryKind::Malformed)
                    .with_bytes(&bytes)
                    .malformed(format!(
                        "{n} byte{} outside a packet (no 0xFF header before)",
                        if n == 1 { "" } else { "s" }
                    )),
            );
        }
    }

    fn flush_unexpected(&mut self, out: &mut VecDeque<Entry>) {
        if let Some((line, time, bytes)) = self.unexpected.take() {
            let mut e = Entry::new(
                line,
                Some(time),
                Direction::FromDevice,
                EntryKind::Unexpected,
            )
            .with_bytes(&bytes);
            let reason = "no command was waiting for a reply";
            e.text = format!("UNEXPECTED: {reason}");
            e.malformed = Some(reason.into());
            out.push_back(e);
        }
    }

    /// Ends the wait for a reply: missing, or truncated if some bytes came.
    fn end_wait(&mut self, why: &str, out: &mut VecDeque<Entry>) {
        let Some(w) = self.waiting.take() else {
            return;
        };
        let name = w.command.name();
        let device = servo_of(&w.command);
        if let Some((line, time)) = w.first {
            let mut e = Entry::new(
                line,
                Some(time),
                Direction::FromDevice,
                EntryKind::Malformed,
            )
            .with_bytes(&w.bytes)
            .malformed(format!(
                "truncated reply to {name}: {} of 2 bytes before {why}",
                w.bytes.len()
            ));
            e.device = device;
            e.command = Some(name.into());
            out.push_back(e);
        } else {
            let mut e = Entry::new(
                w.line,
                Some(w.time),
                Direction::FromDevice,
                EntryKind::Missing,
            );
            e.device = device;
            e.command = Some(name.into());
            e.text = format!("NO REPLY to {name} (none before {why})");
            out.push_back(e);
        }
    }

    pub(super) fn written(
        &mut self,
        line: u64,
        time: &str,
        bytes: &[u8],
        out: &mut VecDeque<Entry>,
    ) {
        self.flush_unexpected(out);
        for &b in bytes {
            if self.decoder.is_idle() && b != robobus_wck::HEADER {
                self.noise.push(line, time, b);
                if self.noise.bytes.len() >= MAX_RUN {
                    self.flush_noise(out);
                }
                continue;
            }
            if b == robobus_wck::HEADER {
                self.flush_noise(out);
                // Half duplex: a new packet means the reply to the last one is over.
                if self.waiting.is_some() {
                    self.end_wait(&format!("the next packet (line {line})"), out);
                }
            }
            if self.decoder.is_idle() {
                self.packet.clear();
                self.packet_start = Some((line, time.to_owned()));
            }
            self.packet.push(b);
            let Some(event) = self.decoder.push(b) else {
                continue;
            };
            let (start_line, start_time) = self
                .packet_start
                .take()
                .unwrap_or_else(|| (line, time.to_owned()));
            let raw = if matches!(event, Err(DecodeError::Truncated { .. })) {
                self.packet.pop();
                let raw = std::mem::take(&mut self.packet);
                self.packet.push(b);
                self.packet_start = Some((line, time.to_owned()));
                raw
            } else {
                std::mem::take(&mut self.packet)
            };
            let e = Entry::new(
                start_line,
                Some(start_time.clone()),
                Direction::ToDevice,
                EntryKind::Request,
            )
            .with_bytes(&raw);
            match event {
                Ok(command) => {
                    let mut e = e;
                    e.device = servo_of(&command);
                    e.command = Some(command.name().into());
                    e.fields = command.fields().map(Field::from).collect();
                    e.text = command.to_string();
                    out.push_back(e);
                    if command.reply_len() > 0 {
                        self.waiting = Some(Waiting {
                            command,
                            line: start_line,
                            time: start_time,
                            bytes: Vec::new(),
                            first: None,
                        });
                    }
                }
                Err(err) => out.push_back(e.malformed(err.to_string())),
            }
        }
        // Noise is emitted per line; a packet in progress may go on in the next line.
        self.flush_noise(out);
    }

    pub(super) fn read(&mut self, line: u64, time: &str, bytes: &[u8], out: &mut VecDeque<Entry>) {
        for &b in bytes {
            let Some(w) = self.waiting.as_mut() else {
                self.unexpected.push(line, time, b);
                if self.unexpected.bytes.len() >= MAX_RUN {
                    self.flush_unexpected(out);
                }
                continue;
            };
            if w.first.is_none() {
                w.first = Some((line, time.to_owned()));
            }
            w.bytes.push(b);
            if w.bytes.len() < robobus_wck::REPLY_LEN {
                continue;
            }
            let Some(w) = self.waiting.take() else {
                continue;
            };
            let (first_line, first_time) = w.first.unwrap_or_else(|| (line, time.to_owned()));
            let mut e = Entry::new(
                first_line,
                Some(first_time),
                Direction::FromDevice,
                EntryKind::Reply,
            )
            .with_bytes(&w.bytes);
            e.device = servo_of(&w.command);
            e.command = Some(w.command.name().into());
            match w.command.decode_reply(&w.bytes) {
                Ok(reply) => {
                    e.fields = reply.fields().map(Field::from).collect();
                    e.text = reply.to_string();
                    out.push_back(e);
                }
                Err(err) => out.push_back(e.malformed(err.to_string())),
            }
        }
        self.flush_unexpected(out);
    }

    pub(super) fn finish(&mut self, out: &mut VecDeque<Entry>) {
        self.flush_noise(out);
        if !self.decoder.is_idle() && !self.packet.is_empty() {
            let (line, time) = self.packet_start.take().unwrap_or_default();
            let n = self.packet.len();
            out.push_back(
                Entry::new(line, Some(time), Direction::ToDevice, EntryKind::Malformed)
                    .with_bytes(&self.packet)
                    .malformed(format!(
                        "truncated packet: the capture ends after {n} bytes"
                    )),
            );
            self.packet.clear();
            self.decoder.reset();
        }
        self.end_wait("the end of the capture", out);
        self.flush_unexpected(out);
    }
}
