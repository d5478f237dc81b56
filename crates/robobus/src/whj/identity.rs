//! [`Identity`]: what a joint says about itself, as a plain value (the bus caches one
//! per joint, the joint handles read it).

use robobus_whj::registers::UniqueId;
use robobus_whj::units::{CurrentScale, FirmwareVersion, Model};

/// What a joint says about itself (registers 0x00..=0x07 and 0x2A..=0x2F).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Identity {
    /// Product (0x02).
    pub model: Model,
    /// Firmware version (0x03), shown as four hex digits (C28).
    pub firmware: FirmwareVersion,
    /// 96-bit unique ID (0x2A..=0x2F).
    pub unique_id: UniqueId,
    /// Node ID register (0x01); differs from the bus ID after an unsaved ID change.
    pub node_id: u16,
    /// Gear reduction ratio (0x07).
    pub reduction_ratio: u16,
    /// Signature register (0x00; 0x1314 on every documented joint).
    pub signature: u16,
}

impl Identity {
    /// The current LSB of this model (1 or 2 mA, C2).
    pub const fn current_scale(&self) -> CurrentScale {
        self.model.current_scale()
    }
}
