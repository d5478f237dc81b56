//! python-can's `udp_multicast` datagram format, encoded and decoded by hand.
//!
//! One UDP datagram carries one message as a msgpack map of exactly 11 keys, in this
//! order: `timestamp` (float64), `arbitration_id` (uint), `is_extended_id`,
//! `is_remote_frame`, `is_error_frame` (bools), `channel` (nil), `dlc` (the payload length
//! in bytes, not the DLC code), `data` (bin), `is_fd`, `bitrate_switch`,
//! `error_state_indicator` (bools). [`encode`] writes exactly what python-can's
//! `pack_message` (msgpack-python, `use_bin_type=True`) writes; [`decode`] accepts any
//! msgpack encoding of such a map, applies python-can's defaults for missing keys and
//! rejects what `can.Message(check=True, ...)` would reject. Nothing a datagram contains can
//! make it panic.

use robobus_whj::frame::{CanFrame, FrameError, len_to_dlc};

/// The 11 keys, in python-can's order.
const KEYS: [&str; 11] = [
    "timestamp",
    "arbitration_id",
    "is_extended_id",
    "is_remote_frame",
    "is_error_frame",
    "channel",
    "dlc",
    "data",
    "is_fd",
    "bitrate_switch",
    "error_state_indicator",
];

/// A python-can message as carried in a datagram (every field python-can sends; a string
/// `channel` is kept, a nil one is `None`).
// The fields mirror python-can's `Message` one to one, flags included.
#[allow(clippy::struct_excessive_bools)]
#[derive(Debug, Clone, PartialEq)]
pub struct PyCanMessage {
    /// Seconds since the Unix epoch (the sender's clock).
    pub timestamp: f64,
    /// The identifier.
    pub arbitration_id: u32,
    /// Whether the identifier is 29-bit.
    pub is_extended_id: bool,
    /// Whether this is a remote (RTR) frame.
    pub is_remote_frame: bool,
    /// Whether this is an error frame.
    pub is_error_frame: bool,
    /// The channel name, if the sender set one.
    pub channel: Option<String>,
    /// The payload length in bytes.
    pub dlc: u32,
    /// The payload.
    pub data: Vec<u8>,
    /// Whether this is a CAN FD frame.
    pub is_fd: bool,
    /// Bit-rate switch.
    pub bitrate_switch: bool,
    /// Error state indicator.
    pub error_state_indicator: bool,
}

/// Why a datagram is not a valid python-can message.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The datagram ended inside a value.
    #[error("datagram truncated at byte {at}")]
    Truncated {
        /// Offset where more bytes were needed.
        at: usize,
    },
    /// The top-level value is not a map.
    #[error("datagram is not a msgpack map (first byte {first:#04x})")]
    NotAMap {
        /// The first byte.
        first: u8,
    },
    /// A map key is not a string.
    #[error("map key at byte {at} is not a string")]
    KeyNotString {
        /// Offset of the key.
        at: usize,
    },
    /// A key python-can's `Message` does not accept.
    #[error("unknown key {key:?} (python-can would raise TypeError)")]
    UnknownKey {
        /// The key.
        key: String,
    },
    /// A key appears twice.
    #[error("key {key:?} appears twice")]
    DuplicateKey {
        /// The key.
        key: String,
    },
    /// A value has the wrong msgpack type for its key.
    #[error("value of {key:?} has the wrong type (msgpack marker {marker:#04x})")]
    WrongType {
        /// The key.
        key: &'static str,
        /// The msgpack marker byte found.
        marker: u8,
    },
    /// A value is out of range for its key.
    #[error("value of {key:?} out of range: {value}")]
    OutOfRange {
        /// The key.
        key: &'static str,
        /// The value, as text.
        value: String,
    },
    /// Bytes follow the map.
    #[error("{count} bytes follow the message map")]
    TrailingBytes {
        /// How many.
        count: usize,
    },
    /// `dlc` does not match the data length (python-can's check).
    #[error("dlc {dlc} does not match {len} data bytes")]
    DlcMismatch {
        /// The `dlc` field.
        dlc: u32,
        /// The data length.
        len: usize,
    },
    /// The flags contradict each other (python-can's check).
    #[error("inconsistent message: {what}")]
    Inconsistent {
        /// Which rule was broken.
        what: &'static str,
    },
    /// A valid python-can message that a [`CanFrame`] cannot hold (remote or error frame).
    #[error("{what} cannot be represented as a CAN FD data frame")]
    NotADataFrame {
        /// What it is.
        what: &'static str,
    },
    /// The payload length is not legal for the frame kind.
    #[error(transparent)]
    Frame(#[from] FrameError),
}

fn put_uint(out: &mut Vec<u8>, v: u64) {
    if let Ok(b @ 0..=0x7f) = u8::try_from(v) {
        out.push(b);
    } else if let Ok(b) = u8::try_from(v) {
        out.extend([0xcc, b]);
    } else if let Ok(h) = u16::try_from(v) {
        out.push(0xcd);
        out.extend(h.to_be_bytes());
    } else if let Ok(w) = u32::try_from(v) {
        out.push(0xce);
        out.extend(w.to_be_bytes());
    } else {
        out.push(0xcf);
        out.extend(v.to_be_bytes());
    }
}

fn put_key(out: &mut Vec<u8>, key: &str) {
    // All keys are shorter than 32 bytes: fixstr.
    out.push(0xa0 | (u8::try_from(key.len()).unwrap_or(0) & 0x1f));
    out.extend(key.as_bytes());
}

fn put_bool(out: &mut Vec<u8>, b: bool) {
    out.push(if b { 0xc3 } else { 0xc2 });
}

/// Encodes `frame` sent at `timestamp` (seconds since the Unix epoch) exactly as
/// python-can's `pack_message` would (channel nil).
pub fn encode(frame: &CanFrame, timestamp: f64) -> Vec<u8> {
    let mut out = Vec::with_capacity(160);
    out.push(0x8b);
    put_key(&mut out, KEYS[0]);
    out.push(0xcb);
    out.extend(timestamp.to_be_bytes());
    put_key(&mut out, KEYS[1]);
    put_uint(&mut out, u64::from(frame.raw_id()));
    put_key(&mut out, KEYS[2]);
    put_bool(&mut out, frame.is_extended());
    put_key(&mut out, KEYS[3]);
    put_bool(&mut out, false);
    put_key(&mut out, KEYS[4]);
    put_bool(&mut out, false);
    put_key(&mut out, KEYS[5]);
    out.push(0xc0);
    put_key(&mut out, KEYS[6]);
    put_uint(&mut out, frame.len() as u64);
    put_key(&mut out, KEYS[7]);
    // At most 64 bytes: bin8.
    out.extend([0xc4, u8::try_from(frame.len()).unwrap_or(0)]);
    out.extend(frame.data());
    put_key(&mut out, KEYS[8]);
    put_bool(&mut out, frame.is_fd());
    put_key(&mut out, KEYS[9]);
    put_bool(&mut out, frame.brs());
    put_key(&mut out, KEYS[10]);
    put_bool(&mut out, frame.esi());
    out
}

/// A msgpack value, as far as python-can messages need it.
enum Value<'a> {
    Nil,
    Bool(bool),
    Int(i128),
    Float(f64),
    Bytes(&'a [u8]),
    Str(&'a [u8]),
    /// An array of small integers (some msgpack encoders write byte lists this way).
    IntArray(Vec<u8>),
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let end = self
            .pos
            .checked_add(n)
            .ok_or(DecodeError::Truncated { at: self.pos })?;
        let s = self
            .buf
            .get(self.pos..end)
            .ok_or(DecodeError::Truncated { at: self.pos })?;
        self.pos = end;
        Ok(s)
    }

    fn byte(&mut self) -> Result<u8, DecodeError> {
        Ok(self.take(1)?.first().copied().unwrap_or(0))
    }

    fn arr<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }

    fn be(&mut self, n: usize) -> Result<u64, DecodeError> {
        Ok(self
            .take(n)?
            .iter()
            .fold(0u64, |acc, b| (acc << 8) | u64::from(*b)))
    }

    fn len_of(&mut self, n: usize) -> Result<usize, DecodeError> {
        let v = self.be(n)?;
        usize::try_from(v).map_err(|_| DecodeError::Truncated { at: self.pos })
    }

    /// Reads one value; `key` names it for errors.
    fn value(&mut self, key: &'static str) -> Result<Value<'a>, DecodeError> {
        let m = self.byte()?;
        Ok(match m {
            0x00..=0x7f => Value::Int(i128::from(m)),
            0xe0..=0xff => Value::Int(i128::from(m.cast_signed())),
            0xc0 => Value::Nil,
            0xc2 => Value::Bool(false),
            0xc3 => Value::Bool(true),
            0xcc => Value::Int(i128::from(self.be(1)?)),
            0xcd => Value::Int(i128::from(self.be(2)?)),
            0xce => Value::Int(i128::from(self.be(4)?)),
            0xcf => Value::Int(i128::from(self.be(8)?)),
            0xd0 => Value::Int(i128::from(i8::from_be_bytes(self.arr()?))),
            0xd1 => Value::Int(i128::from(i16::from_be_bytes(self.arr()?))),
            0xd2 => Value::Int(i128::from(i32::from_be_bytes(self.arr()?))),
            0xd3 => Value::Int(i128::from(i64::from_be_bytes(self.arr()?))),
            0xca => Value::Float(f64::from(f32::from_be_bytes(self.arr()?))),
            0xcb => Value::Float(f64::from_bits(self.be(8)?)),
            0xc4..=0xc6 => {
                let n = self.len_of(1 << (m - 0xc4))?;
                Value::Bytes(self.take(n)?)
            }
            0xa0..=0xbf => Value::Str(self.take(usize::from(m & 0x1f))?),
            0xd9..=0xdb => {
                let n = self.len_of(1 << (m - 0xd9))?;
                Value::Str(self.take(n)?)
            }
            0x90..=0x9f | 0xdc | 0xdd => {
                let n = match m {
                    0xdc => self.len_of(2)?,
                    0xdd => self.len_of(4)?,
                    _ => usize::from(m & 0x0f),
                };
                if n > 64 {
                    return Err(DecodeError::OutOfRange {
                        key,
                        value: format!("{n} array items"),
                    });
                }
                let mut items = Vec::with_capacity(n);
                for _ in 0..n {
                    match self.value(key)? {
                        Value::Int(i) => {
                            items.push(u8::try_from(i).map_err(|_| DecodeError::OutOfRange {
                                key,
                                value: i.to_string(),
                            })?);
                        }
                        _ => return Err(DecodeError::WrongType { key, marker: m }),
                    }
                }
                Value::IntArray(items)
            }
            _ => return Err(DecodeError::WrongType { key, marker: m }),
        })
    }
}

fn want_bool(key: &'static str, v: &Value<'_>, marker: u8) -> Result<bool, DecodeError> {
    match v {
        Value::Bool(b) => Ok(*b),
        // Python treats 0/1 as falsy/truthy; python-can stores them as given.
        Value::Int(i) => Ok(*i != 0),
        Value::Nil => Ok(false),
        _ => Err(DecodeError::WrongType { key, marker }),
    }
}

/// Decodes a datagram into a python-can message, or says exactly why it is not one.
pub fn decode(datagram: &[u8]) -> Result<PyCanMessage, DecodeError> {
    let mut r = Reader {
        buf: datagram,
        pos: 0,
    };
    let first = r.byte()?;
    let count = match first {
        0x80..=0x8f => usize::from(first & 0x0f),
        0xde => r.len_of(2)?,
        0xdf => r.len_of(4)?,
        _ => return Err(DecodeError::NotAMap { first }),
    };
    let mut msg = PyCanMessage {
        timestamp: 0.0,
        arbitration_id: 0,
        is_extended_id: true,
        is_remote_frame: false,
        is_error_frame: false,
        channel: None,
        dlc: 0,
        data: Vec::new(),
        is_fd: false,
        bitrate_switch: false,
        error_state_indicator: false,
    };
    let mut seen = [false; 11];
    let mut dlc: Option<u32> = None;
    for _ in 0..count {
        let at = r.pos;
        let Value::Str(key_bytes) = r.value("<key>")? else {
            return Err(DecodeError::KeyNotString { at });
        };
        let idx = KEYS
            .iter()
            .position(|k| k.as_bytes() == key_bytes)
            .ok_or_else(|| DecodeError::UnknownKey {
                key: String::from_utf8_lossy(key_bytes).into_owned(),
            })?;
        let key = KEYS.get(idx).copied().unwrap_or("<key>");
        if seen.get(idx).copied().unwrap_or(false) {
            return Err(DecodeError::DuplicateKey {
                key: key.to_owned(),
            });
        }
        if let Some(s) = seen.get_mut(idx) {
            *s = true;
        }
        let marker = r.buf.get(r.pos).copied().unwrap_or(0);
        let v = r.value(key)?;
        set_field(&mut msg, &mut dlc, idx, key, v, marker)?;
    }
    let rest = datagram.len().saturating_sub(r.pos);
    if rest != 0 {
        return Err(DecodeError::TrailingBytes { count: rest });
    }
    let len = msg.data.len();
    msg.dlc = match dlc {
        Some(d) => d,
        None => u32::try_from(len).unwrap_or(u32::MAX),
    };
    check(&msg)?;
    Ok(msg)
}

/// Stores the value of key number `idx` (in [`KEYS`] order) into `msg`.
fn set_field(
    msg: &mut PyCanMessage,
    dlc: &mut Option<u32>,
    idx: usize,
    key: &'static str,
    v: Value<'_>,
    marker: u8,
) -> Result<(), DecodeError> {
    match idx {
        0 => {
            msg.timestamp = match v {
                Value::Float(f) => f,
                Value::Int(i) => i as f64,
                _ => return Err(DecodeError::WrongType { key, marker }),
            };
        }
        1 => {
            let Value::Int(i) = v else {
                return Err(DecodeError::WrongType { key, marker });
            };
            msg.arbitration_id = u32::try_from(i).map_err(|_| DecodeError::OutOfRange {
                key,
                value: i.to_string(),
            })?;
        }
        2 => msg.is_extended_id = want_bool(key, &v, marker)?,
        3 => msg.is_remote_frame = want_bool(key, &v, marker)?,
        4 => msg.is_error_frame = want_bool(key, &v, marker)?,
        5 => {
            msg.channel = match v {
                Value::Nil => None,
                Value::Str(s) => Some(String::from_utf8_lossy(s).into_owned()),
                Value::Int(i) => Some(i.to_string()),
                _ => return Err(DecodeError::WrongType { key, marker }),
            };
        }
        6 => match v {
            Value::Nil => *dlc = None,
            Value::Int(i) => {
                *dlc = Some(u32::try_from(i).map_err(|_| DecodeError::OutOfRange {
                    key,
                    value: i.to_string(),
                })?);
            }
            _ => return Err(DecodeError::WrongType { key, marker }),
        },
        7 => {
            msg.data = match v {
                Value::Nil => Vec::new(),
                Value::Bytes(b) | Value::Str(b) => b.to_vec(),
                Value::IntArray(a) => a,
                _ => return Err(DecodeError::WrongType { key, marker }),
            };
        }
        8 => msg.is_fd = want_bool(key, &v, marker)?,
        9 => msg.bitrate_switch = want_bool(key, &v, marker)?,
        _ => msg.error_state_indicator = want_bool(key, &v, marker)?,
    }
    Ok(())
}

/// python-can's `Message._check` rules.
fn check(msg: &PyCanMessage) -> Result<(), DecodeError> {
    if !msg.timestamp.is_finite() || msg.timestamp < 0.0 {
        return Err(DecodeError::OutOfRange {
            key: "timestamp",
            value: msg.timestamp.to_string(),
        });
    }
    if msg.is_remote_frame && msg.is_error_frame {
        return Err(DecodeError::Inconsistent {
            what: "both a remote and an error frame",
        });
    }
    if msg.is_remote_frame && msg.is_fd {
        return Err(DecodeError::Inconsistent {
            what: "CAN FD does not have remote frames",
        });
    }
    let max_id = if msg.is_extended_id {
        0x1FFF_FFFF
    } else {
        0x7FF
    };
    if msg.arbitration_id > max_id {
        return Err(DecodeError::OutOfRange {
            key: "arbitration_id",
            value: format!("{:#x}", msg.arbitration_id),
        });
    }
    let max_len = if msg.is_fd { 64 } else { 8 };
    if msg.dlc > max_len {
        return Err(DecodeError::OutOfRange {
            key: "dlc",
            value: msg.dlc.to_string(),
        });
    }
    if !msg.is_remote_frame && msg.dlc as usize != msg.data.len() {
        return Err(DecodeError::DlcMismatch {
            dlc: msg.dlc,
            len: msg.data.len(),
        });
    }
    if !msg.is_fd && (msg.bitrate_switch || msg.error_state_indicator) {
        return Err(DecodeError::Inconsistent {
            what: "bitrate_switch / error_state_indicator set on a classic frame",
        });
    }
    Ok(())
}

impl PyCanMessage {
    /// The message as a data frame (remote and error frames are refused).
    pub fn to_frame(&self) -> Result<CanFrame, DecodeError> {
        if self.is_error_frame {
            return Err(DecodeError::NotADataFrame {
                what: "an error frame",
            });
        }
        if self.is_remote_frame {
            return Err(DecodeError::NotADataFrame {
                what: "a remote frame",
            });
        }
        let id = if self.is_extended_id {
            CanFrame::extended_id(self.arbitration_id)?
        } else {
            let raw = u16::try_from(self.arbitration_id).map_err(|_| FrameError::IdOutOfRange {
                raw: self.arbitration_id,
            })?;
            CanFrame::standard_id(raw)?
        };
        if self.is_fd {
            if len_to_dlc(self.data.len()).is_none() {
                return Err(FrameError::IllegalFdLength {
                    len: self.data.len(),
                }
                .into());
            }
            Ok(CanFrame::new_fd(id, &self.data)?
                .with_brs(self.bitrate_switch)
                .with_esi(self.error_state_indicator))
        } else {
            Ok(CanFrame::new_classic(id, &self.data)?)
        }
    }
}

/// Decodes a datagram straight into a data frame and its timestamp.
pub fn decode_frame(datagram: &[u8]) -> Result<(CanFrame, f64), DecodeError> {
    let msg = decode(datagram)?;
    Ok((msg.to_frame()?, msg.timestamp))
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn frame(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
    }

    /// Built byte by byte from the msgpack spec, independent of `encode`: python-can's
    /// packing of Message(timestamp=1.5, `arbitration_id=0x123`, `is_extended_id=False`,
    /// data=[0xDE,0xAD,0xBE,0xEF], `is_fd=True`, `bitrate_switch=True`).
    fn reference_datagram() -> Vec<u8> {
        let mut v = vec![0x8b];
        v.extend(b"\xa9timestamp\xcb\x3f\xf8\x00\x00\x00\x00\x00\x00");
        v.extend(b"\xaearbitration_id\xcd\x01\x23");
        v.extend(b"\xaeis_extended_id\xc2");
        v.extend(b"\xafis_remote_frame\xc2");
        v.extend(b"\xaeis_error_frame\xc2");
        v.extend(b"\xa7channel\xc0");
        v.extend(b"\xa3dlc\x04");
        v.extend(b"\xa4data\xc4\x04\xde\xad\xbe\xef");
        v.extend(b"\xa5is_fd\xc3");
        v.extend(b"\xaebitrate_switch\xc3");
        v.extend(b"\xb5error_state_indicator\xc2");
        v
    }

    #[test]
    fn encodes_like_msgpack_python() {
        let f = frame(0x123, &[0xDE, 0xAD, 0xBE, 0xEF]);
        assert_eq!(encode(&f, 1.5), reference_datagram());
    }

    #[test]
    fn decodes_the_reference_and_round_trips() {
        let (f, ts) = decode_frame(&reference_datagram()).unwrap();
        assert_eq!(f, frame(0x123, &[0xDE, 0xAD, 0xBE, 0xEF]));
        assert!((ts - 1.5).abs() < f64::EPSILON);
        let ext = CanFrame::new_fd(CanFrame::extended_id(0x1ABC_DEF0).unwrap(), &[7; 64])
            .unwrap()
            .with_brs(false)
            .with_esi(true);
        assert_eq!(decode_frame(&encode(&ext, 2.25)).unwrap(), (ext, 2.25));
        let classic =
            CanFrame::new_classic(CanFrame::standard_id(0x7FF).unwrap(), &[1, 2]).unwrap();
        assert_eq!(decode_frame(&encode(&classic, 0.0)).unwrap().0, classic);
    }

    #[test]
    fn applies_python_can_defaults_and_checks() {
        // {"arbitration_id": 5, "data": b"\x01"}: is_extended_id defaults to True.
        let mut d = vec![0x82];
        d.extend(b"\xaearbitration_id\x05\xa4data\xc4\x01\x01");
        let f = decode_frame(&d).unwrap().0;
        assert!(f.is_extended() && f.raw_id() == 5 && f.data() == [1] && !f.is_fd());
        // Unknown key.
        let mut d = vec![0x81];
        d.extend(b"\xa3foo\xc0");
        assert_eq!(
            decode(&d),
            Err(DecodeError::UnknownKey { key: "foo".into() })
        );
        // dlc mismatch.
        let mut d = vec![0x82];
        d.extend(b"\xa3dlc\x03\xa4data\xc4\x01\x01");
        assert_eq!(decode(&d), Err(DecodeError::DlcMismatch { dlc: 3, len: 1 }));
        // Illegal FD length passes python-can's check but is not a CanFrame.
        let mut d = vec![0x82];
        d.extend(b"\xa5is_fd\xc3\xa4data\xc4\x0a\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00");
        assert!(decode(&d).is_ok());
        assert!(matches!(decode_frame(&d), Err(DecodeError::Frame(_))));
        // Error frame.
        let mut d = vec![0x81];
        d.extend(b"\xaeis_error_frame\xc3");
        assert_eq!(
            decode_frame(&d),
            Err(DecodeError::NotADataFrame {
                what: "an error frame"
            })
        );
        // Truncated, trailing, not a map.
        let full = reference_datagram();
        assert!(matches!(
            decode(&full[..full.len() - 1]),
            Err(DecodeError::Truncated { .. })
        ));
        let mut long = full.clone();
        long.push(0);
        assert_eq!(decode(&long), Err(DecodeError::TrailingBytes { count: 1 }));
        assert_eq!(decode(&[0x93]), Err(DecodeError::NotAMap { first: 0x93 }));
        assert!(matches!(decode(&[]), Err(DecodeError::Truncated { at: 0 })));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(1000))]

        #[test]
        fn arbitrary_datagrams_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
            let _ = decode_frame(&bytes);
        }

        #[test]
        fn mutated_valid_datagrams_never_panic(
            pos in 0usize..160, byte in any::<u8>(), cut in 0usize..170,
            data in proptest::collection::vec(any::<u8>(), 0..=8),
        ) {
            let f = CanFrame::new_fd_padded(CanFrame::standard_id(0x42).unwrap(), &data).unwrap();
            let mut d = encode(&f, 123.456);
            if let Some(b) = d.get_mut(pos) { *b = byte; }
            d.truncate(cut);
            let _ = decode_frame(&d);
        }

        #[test]
        fn round_trip(id in 0u16..=0x7FF, len_code in 0u8..16, fill in any::<u8>(), brs: bool, esi: bool, ts in 0.0f64..4e9) {
            let len = robobus_whj::frame::dlc_to_len(len_code).unwrap();
            let data: Vec<u8> = (0..len).map(|i| fill.wrapping_add(u8::try_from(i).unwrap())).collect();
            let f = frame(id, &data).with_brs(brs).with_esi(esi);
            prop_assert_eq!(decode_frame(&encode(&f, ts)).unwrap(), (f, ts));
        }
    }
}
