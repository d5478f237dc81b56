//! WHJ frames of a candump log: each frame a request, a reply or another kind by its CAN
//! ID, decoded and shown by the protocol core (`Display`, `fields()`), and requests paired
//! with their replies as the client pairs them.

use robobus_whj::reply::Reply as WhjReply;
use robobus_whj::request::Request;
use robobus_whj::units::CurrentScale;
use robobus_whj::{Address, CanFrame, JointId};

use super::{Direction, Entry, EntryKind};

/// What the WHJ decoder remembers: the register count each joint last asked for (a read
/// reply is padded to a CAN FD length; the request says how many words are real).
#[derive(Debug, Default)]
pub(super) struct WhjState {
    asked: [Option<u8>; 31],
    /// Per joint, the point-to-point request still waiting for its reply: its line, time,
    /// what it expects and its description. Paired as the client pairs them
    /// (`Expect::answers`): by the joint's reply ID and the reply's content.
    waiting: [Option<Waited>; 31],
}

#[derive(Debug, Clone)]
struct Waited {
    line: u64,
    time: Option<String>,
    expect: crate::whj::session::Expect,
    what: String,
}

impl WhjState {
    /// Pairs entry `e` (just decoded from `frame`) with the requests waiting: a request
    /// ends the wait of an earlier one to the same joint (that one is missing its reply,
    /// returned here to be shown before `e`); a reply is credited to the request it
    /// answers, else marked unexpected (nobody asked, or it answers another request).
    pub(super) fn pair(&mut self, frame: &CanFrame, e: &mut Entry) -> Option<Entry> {
        match e.kind {
            // A malformed request that a joint answers (with a command error) waits for it.
            EntryKind::Malformed if e.direction == Direction::ToDevice => {
                let (joint, _) = Request::decode(frame).err()?.response()?;
                self.wait(
                    joint,
                    e,
                    crate::whj::session::Expect::CmdErr,
                    "a malformed request".into(),
                )
            }
            EntryKind::Request => {
                let req = Request::decode(frame).ok()?;
                let joint = req.joint()?;
                let expect = crate::whj::session::Expect::of(&req)?;
                self.wait(joint, e, expect, crate::whj::session::describe(&req))
            }
            EntryKind::Reply => {
                let Ok(reply) = WhjReply::from_frame(frame) else {
                    return None;
                };
                if matches!(
                    reply,
                    WhjReply::BroadcastFeedback { .. } | WhjReply::BroadcastRegister { .. }
                ) {
                    return None;
                }
                let slot = self.waiting.get_mut(usize::from(reply.joint().get()))?;
                let why = match slot
                    .as_ref()
                    .map(|w| (w.line, w.expect.answers(&reply, frame)))
                {
                    Some((_, Ok(()))) => {
                        *slot = None;
                        return None;
                    }
                    Some((line, Err((_, why)))) => {
                        format!("answers no waiting request ({why}; waiting since line {line})")
                    }
                    None => "no request to this joint was waiting for it".into(),
                };
                e.kind = EntryKind::Unexpected;
                e.text = format!("UNEXPECTED: {why}: {}", e.text);
                e.malformed = Some(why);
                None
            }
            _ => None,
        }
    }

    /// Joint `joint` now waits for `expect` (the request of entry `e`); an earlier wait of
    /// the same joint ends as a missing reply, returned.
    fn wait(
        &mut self,
        joint: JointId,
        e: &Entry,
        expect: crate::whj::session::Expect,
        what: String,
    ) -> Option<Entry> {
        let slot = self.waiting.get_mut(usize::from(joint.get()))?;
        let before = slot.take().map(|w| w.missing(&format!("line {}", e.line)));
        *slot = Some(Waited {
            line: e.line,
            time: e.time.clone(),
            expect,
            what,
        });
        before
    }

    /// The requests still waiting at the end of the capture, as missing replies.
    pub(super) fn finish(&mut self) -> Vec<Entry> {
        let mut out: Vec<Entry> = self
            .waiting
            .iter_mut()
            .filter_map(Option::take)
            .map(|w| w.missing("the end of the capture"))
            .collect();
        out.sort_by_key(|e| e.line);
        out
    }
}

impl Waited {
    fn missing(self, before: &str) -> Entry {
        let mut e = Entry::new(
            self.line,
            self.time,
            Direction::FromDevice,
            EntryKind::Missing,
        );
        e.text = format!("NO REPLY to {} (none before {before})", self.what);
        e.command = Some(self.expect.name().into());
        e
    }
}

impl WhjState {
    pub(super) fn decode(&mut self, frame: &CanFrame, scale: CurrentScale) -> Entry {
        let mut e =
            Entry::new(0, None, Direction::Unknown, EntryKind::Other).with_bytes(frame.data());
        e.can_id = Some(frame.raw_id());
        let Some(raw) = frame.standard_raw_id() else {
            return e.malformed("extended 29-bit identifier (WHJ uses 11-bit IDs)");
        };
        e.direction = Direction::FromDevice;
        match Address::from_raw(raw) {
            Address::Joint { function, .. } | Address::InterfaceBoard { function }
                if function.is_request() =>
            {
                self.request(e, frame, scale)
            }
            Address::Broadcast(_) => self.request(e, frame, scale),
            Address::Joint { .. }
            | Address::BroadcastFeedback(_)
            | Address::BroadcastRegisterReply(_) => self.reply(e, frame, scale),
            Address::InterfaceBoard { function } => {
                e.text = format!("interface board {function:?} frame (not decoded)");
                e
            }
            Address::EndBoardFeedback | Address::EndBoardRegisterReply => {
                match robobus_whj::EndBoardReply::decode(frame.data()) {
                    Some(r) => {
                        e.text = r.to_string();
                        e
                    }
                    None => e.malformed("end-board reply shorter than its 8-byte header"),
                }
            }
            Address::IapData => {
                e.direction = Direction::ToDevice;
                e.text = "firmware update data (not decoded)".into();
                e
            }
            Address::Unknown(id) => {
                e.direction = Direction::Unknown;
                e.malformed(format!("CAN ID {id:#05x} is not a WHJ ID"))
            }
        }
    }

    fn request(&mut self, mut e: Entry, frame: &CanFrame, scale: CurrentScale) -> Entry {
        e.direction = Direction::ToDevice;
        let req = match Request::decode(frame) {
            Ok(r) => r,
            Err(m) => {
                e.device = m.joint.map(JointId::get);
                return e.malformed(m.reason.to_string());
            }
        };
        if let Request::Read { joint, range } = req
            && let Some(slot) = self.asked.get_mut(usize::from(joint.get()))
        {
            *slot = Some(range.count());
        }
        e.kind = EntryKind::Request;
        e.device = req.joint().map(JointId::get);
        e.described(req.name(), &req.fields(scale), req.display(scale))
    }

    fn reply(&self, mut e: Entry, frame: &CanFrame, scale: CurrentScale) -> Entry {
        let reply = match WhjReply::from_frame(frame) {
            Ok(r) => r,
            Err(err) => return e.malformed(err.reason.to_string()),
        };
        // A read reply is padded to a CAN FD length: the request said how many words.
        let reply = match reply {
            WhjReply::Read { joint, addr, words } => WhjReply::Read {
                joint,
                addr,
                words: match self.asked.get(usize::from(joint.get())).copied().flatten() {
                    Some(n) => words.truncated(usize::from(n)),
                    None => words,
                },
            },
            other => other,
        };
        e.kind = EntryKind::Reply;
        e.device = Some(reply.joint().get());
        e.described(reply.name(), &reply.fields(scale), reply.display(scale))
    }
}
