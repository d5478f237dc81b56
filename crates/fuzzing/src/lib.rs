//! The properties robobus's fuzz targets check, as plain functions.
//!
//! Each `check` takes arbitrary bytes and returns `Err(Violation)` when a decoder or
//! parser breaks a promise; "no panic" is only the first of them:
//!
//! - a decoded packet or frame encodes back to the same bytes ([`wck_stream`],
//!   [`wck_reply`], [`whj_request`], [`whj_reply`], [`candump_line`], [`hex_line`]);
//! - the wCK stream decoder never yields a packet whose checksum does not verify;
//! - a text parser accepts its input or fails at a position inside it ([`motion_text`],
//!   [`program_text`], [`robot_toml`]), and what it accepts it prints back the same
//!   ([`id_list`], [`register_name`]);
//! - a capture of any content replays to a bounded number of entries ([`replay`]);
//! - the client credits a reply only to a request it can answer ([`wck_matching`],
//!   [`whj_matching`]: seeded streams of honest, late, stray and foreign replies on a
//!   virtual clock, and every value a read returns must be the honest one);
//! - no allocation grows beyond the input's size times a small constant
//!   ([`alloc::check_bounded`], fed by the allocator the fuzz binaries install).
//!
//! The checks are generic where a test must be able to break the checked code on purpose
//! (`*_with`): the test suite shows each property catches a decoder that skips its
//! checksum, a frame decoder that drops a field, a parser that reports a position
//! outside its input, a client that takes the first bytes it sees.

pub mod alloc;
mod matching;
mod parsers;
mod protocols;

pub use matching::{wck_matching, wck_matching_with, whj_matching, whj_matching_with};
pub use parsers::{
    candump_line, hex_line, id_list, motion_text, position_inside, program_text, register_name,
    replay, robot_toml,
};
pub use protocols::{
    PacketStream, wck_reply, wck_stream, wck_stream_with, whj_reply, whj_reply_with, whj_request,
};

/// A broken promise: what was fed and what went wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Violation(pub String);

impl std::fmt::Display for Violation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Violation {}

/// What every check returns.
pub type Checked = Result<(), Violation>;

macro_rules! ensure {
    ($cond:expr, $($msg:tt)*) => {
        if !$cond {
            return Err($crate::Violation(format!($($msg)*)));
        }
    };
}
pub(crate) use ensure;

/// A check: arbitrary bytes in, a violation out.
pub type Check = fn(&[u8]) -> Checked;

/// Every target by name, as `scripts/fuzz` and the seed-corpus test list them.
pub const TARGETS: &[(&str, Check)] = &[
    ("wck_stream", wck_stream),
    ("wck_reply", wck_reply),
    ("whj_request", whj_request),
    ("whj_reply", whj_reply),
    ("candump_line", candump_line),
    ("hex_line", hex_line),
    ("replay", replay),
    ("robot_toml", robot_toml),
    ("motion_text", motion_text),
    ("program_text", program_text),
    ("id_list", id_list),
    ("register_name", register_name),
    ("wck_matching", wck_matching),
    ("whj_matching", whj_matching),
];
