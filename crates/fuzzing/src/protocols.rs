//! The protocol decoders: the wCK stream and reply decoders, the WHJ request and reply
//! (broadcast included) decoders.

use robobus_wck::{
    Command, DecodeError, ServoId, StreamDecoder, checksum_range, decode_packet, xor7,
};
use robobus_whj::{CanFrame, Reply, Request};

use crate::{Checked, ensure};

/// A byte-at-a-time packet decoder, as [`StreamDecoder`] is (a test can wrap one to
/// break it on purpose).
pub trait PacketStream {
    /// Feeds one byte; a complete packet (or a broken one) when one ends.
    fn push(&mut self, byte: u8) -> Option<Result<Command, DecodeError>>;
    /// The raw bytes of the packet just returned.
    fn last_packet(&self) -> &[u8];
}

impl PacketStream for StreamDecoder {
    fn push(&mut self, byte: u8) -> Option<Result<Command, DecodeError>> {
        StreamDecoder::push(self, byte)
    }
    fn last_packet(&self) -> &[u8] {
        StreamDecoder::last_packet(self)
    }
}

/// The wCK device-side stream decoder on arbitrary bytes.
pub fn wck_stream(data: &[u8]) -> Checked {
    wck_stream_with(&mut StreamDecoder::new(), data)
}

/// [`wck_stream`] on any [`PacketStream`]: every packet it accepts starts with the header,
/// carries the correct checksum, has its command's length and encodes back to a packet of
/// the same command; a checksum it rejects really is wrong.
pub fn wck_stream_with(decoder: &mut impl PacketStream, data: &[u8]) -> Checked {
    for (at, &byte) in data.iter().enumerate() {
        match decoder.push(byte) {
            Some(Ok(command)) => {
                let raw = decoder.last_packet();
                ensure!(
                    raw.first() == Some(&0xFF),
                    "byte {at}: packet {raw:02X?} without the header"
                );
                let Some((&checksum, _)) = raw.split_last() else {
                    return Err(crate::Violation(format!("byte {at}: an empty packet")));
                };
                let computed = xor7(raw.get(checksum_range(raw)).unwrap_or_default());
                ensure!(
                    computed == checksum,
                    "byte {at}: packet {raw:02X?} accepted with checksum {checksum:#04X}, \
                     computed {computed:#04X}"
                );
                ensure!(
                    raw.len() == command.encoded_len(),
                    "byte {at}: {} bytes for {command} ({} encoded)",
                    raw.len(),
                    command.encoded_len()
                );
                // Bytes the manual leaves arbitrary (a status read's data byte) are written
                // as zeros: the encoding decodes to the same command, not to the same bytes.
                let encoded = command.encode();
                ensure!(
                    decode_packet(encoded.as_bytes()) == Ok(command),
                    "byte {at}: {raw:02X?} decoded to {command}, whose encoding {:02X?} does \
                     not decode back to it",
                    encoded.as_bytes()
                );
            }
            Some(Err(DecodeError::BadChecksum { computed, received })) => {
                ensure!(
                    computed != received,
                    "byte {at}: checksum {received:#04X} refused though it is the computed one"
                );
            }
            Some(Err(_)) | None => {}
        }
    }
    Ok(())
}

/// The command a wCK reply answers: a packet at the start of `data` when one decodes
/// (its length is `data[0] % 9`), else a status read of servo `data[0] % 31`; and the
/// reply bytes after it.
fn command_and_reply(data: &[u8]) -> Option<(Command, &[u8])> {
    let (&first, rest) = data.split_first()?;
    let len = usize::from(first % 9);
    if let Some(packet) = rest.get(..len)
        && let Ok(command) = decode_packet(packet)
    {
        return Some((command, rest.get(len..).unwrap_or_default()));
    }
    let id = ServoId::new(first % 31).ok()?;
    Some((Command::StatusRead { id }, rest))
}

/// The wCK reply decoder: a reply it accepts has its command's reply length and is what
/// a module sends for that value (it re-encodes to the same bytes).
pub fn wck_reply(data: &[u8]) -> Checked {
    let Some((command, reply)) = command_and_reply(data) else {
        return Ok(());
    };
    let reply = reply.get(..reply.len().min(8)).unwrap_or_default();
    if let Ok(decoded) = command.decode_reply(reply) {
        ensure!(
            reply.len() == command.reply_len(),
            "{command}: a {}-byte reply accepted ({} expected)",
            reply.len(),
            command.reply_len()
        );
        let again = decoded.to_bytes();
        let back = command.decode_reply(again.get(..reply.len()).unwrap_or(&again));
        ensure!(
            back.as_ref() == Ok(&decoded),
            "{command}: reply {reply:02X?} decoded to {decoded}, which a module sends as \
             {again:02X?}, which decodes to {back:?}"
        );
        // Replies whose every bit means something must be the very bytes a module sends
        // (the others have bits the manual leaves arbitrary, such as an I/O read's upper
        // output bits and a 10-bit read's spare bits).
        if !matches!(
            command,
            Command::StatusRead { .. } | Command::Move { .. } | Command::Passive { .. }
        ) {
            return Ok(());
        }
        ensure!(
            again.get(..reply.len()) == Some(reply),
            "{command}: reply {reply:02X?} decoded to {decoded}, which a module sends as \
             {again:02X?}"
        );
    }
    Ok(())
}

/// A CAN (FD) frame from arbitrary bytes: an 11-bit identifier from the first two, FD and
/// BRS from the third, the rest cut to the largest legal payload length.
pub(crate) fn frame_of(data: &[u8]) -> Option<CanFrame> {
    let (head, payload) = data.split_at_checked(3)?;
    let raw = u16::from_le_bytes([head[0], head[1]]) & 0x7FF;
    let id = CanFrame::standard_id(raw).ok()?;
    let fd = head[2] & 1 != 0;
    if fd {
        const LENGTHS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];
        let len = LENGTHS
            .iter()
            .copied()
            .filter(|&l| l <= payload.len())
            .max()
            .unwrap_or(0);
        let f = CanFrame::new_fd(id, payload.get(..len)?).ok()?;
        Some(f.with_brs(head[2] & 2 != 0))
    } else {
        CanFrame::new_classic(id, payload.get(..payload.len().min(8))?).ok()
    }
}

/// The WHJ request decoder (point-to-point, servo, status, broadcast): a request it
/// accepts encodes back to the same identifier and payload.
pub fn whj_request(data: &[u8]) -> Checked {
    let Some(frame) = frame_of(data) else {
        return Ok(());
    };
    let frame = canonical_broadcast(frame);
    whj_round_trip(
        &frame,
        "request",
        |f| Request::from_frame(f).ok(),
        Request::to_frame,
    )
}

/// Broadcast frames carry bytes and bits the protocol gives no meaning: the high nibble of
/// the reply mask byte (0x0F, 0x4F, 0x7F), byte 49 of a register frame (0xFF), the rest of
/// a register slot whose first byte is 0xFF (no operation), and the rest of a position or
/// current slot whose top byte is 0x7F ("no data"). A
/// joint ignores them and so does the decoder; the encoder writes them as the protocol
/// says. They are set so here before the comparison.
fn canonical_broadcast(frame: CanFrame) -> CanFrame {
    use robobus_whj::broadcast::{CURRENT_NO_DATA, POSITION_NO_DATA};
    let id = frame.raw_id();
    if !frame.is_fd() || !matches!(id, 0x0F | 0x2F | 0x4F | 0x7F) {
        return frame;
    }
    let mut d = frame.data().to_vec();
    let slots = |d: &mut Vec<u8>, size: usize, filler: &[u8]| {
        for i in 0..7 {
            if let Some(slot) = d.get_mut(i * size..i * size + size)
                && slot[3] == 0x7F
            {
                slot.copy_from_slice(filler);
            }
        }
    };
    match (id, d.len()) {
        (0x0F, 64) => {
            // A slot whose first byte is 0xFF holds no operation: its other bytes are
            // padding.
            for slot in d[..49].chunks_mut(7) {
                if slot[0] == 0xFF {
                    slot.fill(0xFF);
                }
            }
            d[49] = 0xFF;
            d[63] &= 0x0F;
        }
        (0x2F, 64) => slots(&mut d, 8, &POSITION_NO_DATA),
        (0x4F, 48) => {
            slots(&mut d, 4, &CURRENT_NO_DATA);
            d[47] &= 0x0F;
        }
        (0x7F, 24) => d[23] &= 0x0F,
        _ => {}
    }
    CanFrame::new_fd(frame.id(), &d).map_or(frame, |f| f.with_brs(frame.brs()))
}

/// The WHJ reply decoder (register replies, feedback, status, broadcast answers).
pub fn whj_reply(data: &[u8]) -> Checked {
    whj_reply_with(data, |f| Reply::from_frame(f).ok(), Reply::to_frame)
}

/// [`whj_reply`] with any decoder and encoder (a test breaks one on purpose).
pub fn whj_reply_with<T: std::fmt::Debug + PartialEq>(
    data: &[u8],
    decode: impl Fn(&CanFrame) -> Option<T>,
    encode: impl Fn(&T) -> CanFrame,
) -> Checked {
    let Some(frame) = frame_of(data) else {
        return Ok(());
    };
    whj_round_trip(&frame, "reply", decode, encode)
}

fn whj_round_trip<T: std::fmt::Debug + PartialEq>(
    frame: &CanFrame,
    what: &str,
    decode: impl Fn(&CanFrame) -> Option<T>,
    encode: impl Fn(&T) -> CanFrame,
) -> Checked {
    let Some(value) = decode(frame) else {
        return Ok(());
    };
    let again = encode(&value);
    let back = decode(&again);
    ensure!(
        back.as_ref() == Some(&value),
        "{what} {frame:?} decoded to {value:?}, whose encoding {again:?} decodes to {back:?}"
    );
    // Broadcast register frames (requests on 0x0F and the joints' answers on 0xF0+ID+1,
    // J6 0x3FE, end board 0xF7) are decoded leniently, as the joints read them (a slot's
    // length byte, GRIP's length prefix, padding of any value): for them the encoding
    // must decode to the same operations, not give the same bytes.
    let raw = frame.raw_id();
    if raw == 0x0F || (0xF2..=0xF8).contains(&raw) || raw == 0x3FE {
        return Ok(());
    }
    ensure!(
        again.raw_id() == frame.raw_id(),
        "{what} {frame:?} decoded to {value:?}, which encodes with identifier {:#X}",
        again.raw_id()
    );
    // FD lengths round up: a sender pads a payload with bytes of any value, which the
    // decoder ignores and the encoder writes as zeros. Up to the shorter of the two the
    // bytes are the same; what the encoding has beyond the frame is zeros.
    let (got, sent) = (again.data(), frame.data());
    let n = got.len().min(sent.len());
    ensure!(
        got.get(..n) == sent.get(..n) && got.iter().skip(n).all(|&b| b == 0),
        "{what} {sent:02X?} on {:#X} decoded to {value:?}, which encodes to {got:02X?}",
        frame.raw_id()
    );
    Ok(())
}
