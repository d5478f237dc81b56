//! `diagnostic_msgs/msg/DiagnosticArray`: what the bridge publishes on `NS/diagnostics`
//! (one status per joint and per bus), written and read with this module's CDR.

use super::{CdrError, MAX_ELEMENTS, MAX_STRING, Reader, Time, Writer};

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct KeyValue {
    /// The key (`temperature_c`).
    pub key: String,
    /// The value, as text.
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DiagnosticStatus {
    /// `OK` 0, `WARN` 1, `ERROR` 2, `STALE` 3.
    pub level: u8,
    /// `robobus: ROBOT joint NAME`, `robobus: ROBOT bus NAME`.
    pub name: String,
    /// Why it is at its level.
    pub message: String,
    /// The device.
    pub hardware_id: String,
    /// What was read.
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/msg/DiagnosticArray` (its `std_msgs/Header` flattened).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DiagnosticArray {
    /// `header.stamp`.
    pub stamp: Time,
    /// `header.frame_id`.
    pub frame_id: String,
    /// One status per joint and per bus.
    pub status: Vec<DiagnosticStatus>,
}

impl DiagnosticArray {
    /// The payload: header and little-endian CDR. At most [`MAX_ELEMENTS`] statuses and
    /// values per status are written, each string at most [`MAX_STRING`] bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.i32(self.stamp.sec);
        w.u32(self.stamp.nanosec);
        w.string_cut(&self.frame_id);
        let status = &self.status[..self.status.len().min(MAX_ELEMENTS)];
        w.count(status.len());
        for s in status {
            w.buf.push(s.level);
            w.string_cut(&s.name);
            w.string_cut(&s.message);
            w.string_cut(&s.hardware_id);
            let values = &s.values[..s.values.len().min(MAX_ELEMENTS)];
            w.count(values.len());
            for kv in values {
                w.string_cut(&kv.key);
                w.string_cut(&kv.value);
            }
        }
        w.buf
    }

    /// Reads a payload (either byte order).
    ///
    /// # Errors
    ///
    /// [`CdrError`] naming the field that does not fit.
    pub fn decode(payload: &[u8]) -> Result<Self, CdrError> {
        let mut r = Reader::new(payload)?;
        let sec = r.i32("header.stamp.sec")?;
        let nanosec = r.u32("header.stamp.nanosec")?;
        let frame_id = r.string("header.frame_id")?;
        // A status takes at least 20 bytes: its level, three empty strings, no values.
        let n = r.count("status", MAX_ELEMENTS, 20)?;
        let mut status = Vec::with_capacity(n);
        for _ in 0..n {
            let level = r.u8("status.level")?;
            let name = r.string("status.name")?;
            let message = r.string("status.message")?;
            let hardware_id = r.string("status.hardware_id")?;
            // A key value takes at least 10 bytes: two empty strings.
            let m = r.count("status.values", MAX_ELEMENTS, 10)?;
            let mut values = Vec::with_capacity(m);
            for _ in 0..m {
                values.push(KeyValue {
                    key: r.string("status.values.key")?,
                    value: r.string("status.values.value")?,
                });
            }
            status.push(DiagnosticStatus {
                level,
                name,
                message,
                hardware_id,
                values,
            });
        }
        Ok(Self {
            stamp: Time { sec, nanosec },
            frame_id,
            status,
        })
    }
}

impl Writer {
    /// A string, cut to [`MAX_STRING`] bytes at a character boundary (a reader bounds its
    /// strings too).
    fn string_cut(&mut self, s: &str) {
        let mut end = s.len().min(MAX_STRING);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        self.string(&s[..end]);
    }
}

impl Reader<'_> {
    fn u8(&mut self, field: &'static str) -> Result<u8, CdrError> {
        Ok(self.take(1, 1, field)?[0])
    }
}
