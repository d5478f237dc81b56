//! CAN and CAN FD frames as plain values.
//!
//! [`CanFrame`] is the one frame type every robobus layer exchanges: the protocol core
//! builds and parses it, links send and receive it, captures read and write it. It holds
//! an 11-bit or 29-bit identifier (`embedded_can::Id`), a payload of a legal length, and
//! the FD flags (FDF, BRS, ESI). WHJ joints use CAN FD base frames with BRS on
//! (the vendor tables' control bits: FDF = 1, BRS = 1, ESI = 0); classic frames stay representable
//! because a bus may carry them.

use core::fmt;

pub use embedded_can::{ExtendedId, Id, StandardId};

/// Largest CAN FD payload in bytes.
pub const MAX_FD_LEN: usize = 64;
/// Largest classic CAN payload in bytes.
pub const MAX_CLASSIC_LEN: usize = 8;

/// Payload length in bytes for each 4-bit DLC code (ISO 11898-1:2015, CAN FD).
const DLC_TO_LEN: [u8; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// The payload length (bytes) a CAN FD DLC code stands for, or `None` for codes above 15.
#[must_use]
pub const fn dlc_to_len(dlc: u8) -> Option<usize> {
    if dlc < 16 {
        Some(DLC_TO_LEN[dlc as usize] as usize)
    } else {
        None
    }
}

#[allow(clippy::cast_possible_truncation)] // dlc < 16
/// The DLC code of a legal CAN FD payload length, or `None` if `len` is not one of
/// 0..=8, 12, 16, 20, 24, 32, 48, 64.
#[must_use]
pub const fn len_to_dlc(len: usize) -> Option<u8> {
    let mut dlc = 0;
    while dlc < 16 {
        if DLC_TO_LEN[dlc] as usize == len {
            return Some(dlc as u8);
        }
        dlc += 1;
    }
    None
}

/// The smallest legal CAN FD payload length that holds `len` bytes (what a sender pads
/// to), or `None` if `len` exceeds 64.
#[must_use]
pub const fn padded_len(len: usize) -> Option<usize> {
    let mut dlc = 0;
    while dlc < 16 {
        if DLC_TO_LEN[dlc] as usize >= len {
            return Some(DLC_TO_LEN[dlc] as usize);
        }
        dlc += 1;
    }
    None
}

/// Why a frame could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The payload length is not a legal CAN FD length.
    #[error(
        "CAN FD payload of {len} bytes is not a legal length (allowed: 0..=8, 12, 16, 20, 24, 32, 48, 64)"
    )]
    IllegalFdLength {
        /// The length that was given.
        len: usize,
    },
    /// A classic CAN frame carries at most 8 bytes.
    #[error("classic CAN payload of {len} bytes is too long (allowed: 0..=8)")]
    ClassicTooLong {
        /// The length that was given.
        len: usize,
    },
    /// The raw identifier does not fit its format.
    #[error(
        "CAN identifier {raw:#x} out of range (allowed: 0..=0x7FF standard, 0..=0x1FFFFFFF extended)"
    )]
    IdOutOfRange {
        /// The identifier that was given.
        raw: u32,
    },
}

/// A CAN FD (or classic CAN) data frame.
///
/// Invariant: `len` is a legal length for the frame's kind (CAN FD: a DLC length;
/// classic: 0..=8), and bytes past `len` in the buffer are zero, so derived equality
/// compares exactly the frame's content.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: Id,
    len: u8,
    data: [u8; MAX_FD_LEN],
    fd: bool,
    brs: bool,
    esi: bool,
}

impl CanFrame {
    /// A CAN FD frame with bit-rate switching on (what WHJ joints send and expect).
    ///
    /// `data` must have a legal CAN FD length; use [`CanFrame::new_fd_padded`] to pad.
    pub fn new_fd(id: impl Into<Id>, data: &[u8]) -> Result<Self, FrameError> {
        if len_to_dlc(data.len()).is_none() {
            return Err(FrameError::IllegalFdLength { len: data.len() });
        }
        Ok(Self::build(id.into(), data, true, true))
    }

    /// A CAN FD frame with BRS on whose payload is `data` padded with zero bytes up to the
    /// next legal CAN FD length (a 10-byte read reply becomes 12 bytes).
    #[allow(clippy::cast_possible_truncation)] // len <= 64
    pub fn new_fd_padded(id: impl Into<Id>, data: &[u8]) -> Result<Self, FrameError> {
        let Some(len) = padded_len(data.len()) else {
            return Err(FrameError::IllegalFdLength { len: data.len() });
        };
        let mut frame = Self::build(id.into(), data, true, true);
        // Padding bytes are already zero; only the length grows.
        frame.len = len as u8;
        Ok(frame)
    }

    /// A classic CAN 2.0 data frame (at most 8 bytes, no FD flags).
    pub fn new_classic(id: impl Into<Id>, data: &[u8]) -> Result<Self, FrameError> {
        if data.len() > MAX_CLASSIC_LEN {
            return Err(FrameError::ClassicTooLong { len: data.len() });
        }
        Ok(Self::build(id.into(), data, false, false))
    }

    /// A standard (11-bit) identifier from a raw value, as an [`Id`].
    pub fn standard_id(raw: u16) -> Result<Id, FrameError> {
        StandardId::new(raw)
            .map(Id::Standard)
            .ok_or(FrameError::IdOutOfRange {
                raw: u32::from(raw),
            })
    }

    /// An extended (29-bit) identifier from a raw value, as an [`Id`].
    pub fn extended_id(raw: u32) -> Result<Id, FrameError> {
        ExtendedId::new(raw)
            .map(Id::Extended)
            .ok_or(FrameError::IdOutOfRange { raw })
    }

    /// An empty CAN FD frame (BRS on); infallible fallback for internal encoders.
    pub(crate) const fn empty_fd(id: StandardId) -> Self {
        Self {
            id: Id::Standard(id),
            len: 0,
            data: [0; MAX_FD_LEN],
            fd: true,
            brs: true,
            esi: false,
        }
    }

    #[allow(clippy::cast_possible_truncation)] // callers checked data.len() <= 64
    fn build(id: Id, data: &[u8], fd: bool, brs: bool) -> Self {
        let mut buf = [0u8; MAX_FD_LEN];
        buf[..data.len()].copy_from_slice(data);
        Self {
            id,
            len: data.len() as u8,
            data: buf,
            fd,
            brs,
            esi: false,
        }
    }

    /// Returns the frame with its BRS (bit-rate switch) flag set as given. Ignored for
    /// classic frames.
    #[must_use]
    pub const fn with_brs(mut self, brs: bool) -> Self {
        self.brs = brs && self.fd;
        self
    }

    /// Returns the frame with its ESI (error state indicator) flag set as given. Ignored
    /// for classic frames.
    #[must_use]
    pub const fn with_esi(mut self, esi: bool) -> Self {
        self.esi = esi && self.fd;
        self
    }

    /// The identifier.
    pub const fn id(&self) -> Id {
        self.id
    }

    /// The raw identifier value (11 or 29 bits).
    pub fn raw_id(&self) -> u32 {
        match self.id {
            Id::Standard(id) => u32::from(id.as_raw()),
            Id::Extended(id) => id.as_raw(),
        }
    }

    /// The 11-bit identifier, or `None` for an extended frame.
    pub fn standard_raw_id(&self) -> Option<u16> {
        match self.id {
            Id::Standard(id) => Some(id.as_raw()),
            Id::Extended(_) => None,
        }
    }

    /// Whether the identifier is a 29-bit extended one.
    pub const fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }

    /// The payload.
    pub fn data(&self) -> &[u8] {
        &self.data[..self.len as usize]
    }

    /// The payload length in bytes.
    pub const fn len(&self) -> usize {
        self.len as usize
    }

    /// Whether the payload is empty.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The 4-bit DLC code sent on the wire.
    pub const fn dlc(&self) -> u8 {
        match len_to_dlc(self.len as usize) {
            Some(dlc) => dlc,
            // Unreachable by the type's invariant; 15 is the only safe answer anyway.
            None => 15,
        }
    }

    /// Whether this is a CAN FD frame (FDF set).
    pub const fn is_fd(&self) -> bool {
        self.fd
    }

    /// Whether the data phase is sent at the data bit rate (BRS).
    pub const fn brs(&self) -> bool {
        self.brs
    }

    /// Whether the sender was error passive (ESI).
    pub const fn esi(&self) -> bool {
        self.esi
    }
}

impl CanFrame {
    /// `ID##<flags><sep><data>` (FD, with FDF = 4 in the flags if `fdf`) or `ID#<sep><data>`.
    fn write_line(&self, f: &mut fmt::Formatter<'_>, fdf: bool, sep: &str) -> fmt::Result {
        if self.is_extended() {
            write!(f, "{:08X}", self.raw_id())?;
        } else {
            write!(f, "{:03X}", self.raw_id())?;
        }
        if self.fd {
            let flags = (u8::from(fdf) << 2) | u8::from(self.brs) | (u8::from(self.esi) << 1);
            write!(f, "##{flags:X}{sep}")?;
        } else {
            write!(f, "#{sep}")?;
        }
        self.data().iter().try_for_each(|b| write!(f, "{b:02X}"))
    }
}

impl fmt::Debug for CanFrame {
    /// candump-like, the data set apart: `201##1 40420F00`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write_line(f, false, " ")
    }
}

impl fmt::Display for CanFrame {
    /// The frame in `cansend` syntax: `001##1020A01` (CAN FD: `##`, then the flags nibble
    /// BRS = 1, ESI = 2), `001#0102` (classic), a 29-bit ID as 8 hex digits. The alternate
    /// form (`{:#}`) also sets FDF = 4 in the flags of an FD frame, as `candump -l` writes
    /// it (`001##5020A01`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write_line(f, f.alternate(), "")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_print_in_cansend_syntax_and_as_candump_writes_them() {
        let f = CanFrame::new_fd(CanFrame::standard_id(0x001).unwrap(), &[0x02, 0x0A, 0x01])
            .unwrap()
            .with_brs(true);
        assert_eq!(std::format!("{f}"), "001##1020A01");
        assert_eq!(std::format!("{f:#}"), "001##5020A01");
        let c = CanFrame::new_classic(CanFrame::extended_id(0x1F).unwrap(), &[1, 2]).unwrap();
        assert_eq!(std::format!("{c:#}"), "0000001F#0102");
    }

    #[test]
    #[allow(clippy::cast_possible_truncation)]
    fn dlc_mapping_is_the_iso_table() {
        let lens: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];
        for (dlc, len) in lens.iter().enumerate() {
            assert_eq!(dlc_to_len(dlc as u8), Some(*len));
            assert_eq!(len_to_dlc(*len), Some(dlc as u8));
        }
        assert_eq!(dlc_to_len(16), None);
        for bad in [9, 10, 11, 13, 15, 17, 33, 63, 65] {
            assert_eq!(len_to_dlc(bad), None, "{bad}");
        }
        assert_eq!(padded_len(10), Some(12));
        assert_eq!(padded_len(13), Some(16));
        assert_eq!(padded_len(49), Some(64));
        assert_eq!(padded_len(65), None);
    }

    #[test]
    fn frames_enforce_lengths() {
        let id = CanFrame::standard_id(0x201).unwrap();
        assert_eq!(
            CanFrame::new_fd(id, &[0; 10]),
            Err(FrameError::IllegalFdLength { len: 10 })
        );
        let f = CanFrame::new_fd_padded(id, &[1; 10]).unwrap();
        assert_eq!(f.len(), 12);
        assert_eq!(f.dlc(), 9);
        assert_eq!(&f.data()[10..], &[0, 0]);
        assert!(f.brs() && f.is_fd() && !f.esi());
        assert_eq!(
            CanFrame::new_classic(id, &[0; 9]),
            Err(FrameError::ClassicTooLong { len: 9 })
        );
        assert_eq!(
            CanFrame::standard_id(0x800),
            Err(FrameError::IdOutOfRange { raw: 0x800 })
        );
        let c = CanFrame::new_classic(id, &[1, 2]).unwrap().with_brs(true);
        assert!(!c.brs() && !c.is_fd());
    }

    #[test]
    fn debug_is_candump_like() {
        let id = CanFrame::standard_id(0x201).unwrap();
        let f = CanFrame::new_fd(id, &[0x40, 0x42, 0x0F, 0x00]).unwrap();
        assert_eq!(format!("{f:?}"), "201##1 40420F00");
    }
}
