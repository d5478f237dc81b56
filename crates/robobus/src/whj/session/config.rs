//! The session's settings ([`JointBusConfig`]) and the controller state it tracks
//! ([`BusState`]): plain values that the session, its driver and the errors share.

use core::fmt;
use core::time::Duration;

use robobus_link::WaitMode;

/// Settings of a [`JointBus`]. `JointBusConfig::default()` follows the protocol reference.
///
/// [`JointBus`]: crate::whj::JointBus
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointBusConfig {
    /// How long one attempt waits for its reply (default 20 ms; a reply normally takes
    /// about 0.2 ms on a real 1 / 5 Mbit/s bus).
    pub reply_timeout: Duration,
    /// Extra attempts for reads and idempotent operations (default 2). Operations that
    /// are not idempotent (set zero, save to flash) are never resent.
    pub retries: u32,
    /// How long [`JointBus::joint`] keeps sending the IAP release before it calls a joint
    /// silent (default 5 s: joints with a staggered power-up stay silent for a while, C33).
    ///
    /// [`JointBus::joint`]: crate::whj::JointBus::joint
    pub connect_timeout: Duration,
    /// Confirm every register read by a second, identical read (status queries and servo
    /// feedback are not confirmed: they change from frame to frame). For links that can
    /// deliver a corrupted payload (fault injection, a gateway without a checksum): a CAN
    /// controller drops corrupted frames itself (CRC), so this is off by default. Without
    /// it, replies are still matched by register, count and length, so a corrupted
    /// request or header is caught; only a flipped data bit is not.
    pub verify_reads: bool,
    /// Largest position step, degrees, that a single position command may make from the
    /// actual position (default 5°, half the joint's 10° protection, C10). Larger moves go
    /// through [`Joint::move_to`] or the cyclic loop's trajectory.
    ///
    /// [`Joint::move_to`]: crate::whj::Joint::move_to
    pub step_limit_deg: f64,
    /// Quiet time after a disable during which nothing is sent to that joint (5 ms, §6.3).
    pub disable_settle: Duration,
    /// Quiet time after a save to flash (50 ms, §6.4).
    pub save_settle: Duration,
    /// How long a request waits for a bus-off controller to recover before it fails
    /// (default 1 s).
    pub bus_recovery_timeout: Duration,
    /// After an error-passive or error-warning report, how long without a new report
    /// before the bus counts as recovered (default 1 s).
    pub error_passive_hold: Duration,
    /// Duplicate detection: how much later than the wire the link may deliver the second
    /// of two frames that followed each other on the wire, or `None` (the default) for the
    /// link's own allowance ([`FrameLink::reply_allowance`]: zero on the in-memory bus and
    /// the simulator on virtual time, 50 µs on `SocketCAN`, 0.2 ms on the UDP bus, 1.5 ms
    /// through an slcan or fdcanusb USB adapter). Two nodes at one ID both answer a
    /// request; the one that lost arbitration sends its answer right after the winner's,
    /// so a reply is held for one frame of its own length on the wire at the WHJ rates
    /// (the loser's; a 16-byte status or servo feedback takes about 0.07 ms at 1 / 5
    /// Mbit/s, a 64-byte frame about 0.15 ms), plus this allowance. Every frame on the
    /// wire meanwhile that the loser's answer had to wait for (a request the client sends
    /// to another joint, which wins arbitration, or another joint's reply with a lower ID)
    /// lengthens the hold by its own wire time. A second, different reply within the hold
    /// fails the request with [`WhjError::DuplicateReply`] instead of crediting either.
    /// Only the request's caller waits for it: requests to other joints go out meanwhile;
    /// the next request on the same reply ID waits for it too. Set it only for a link
    /// that delivers later than it says (a gateway, an adapter behind a hub).
    ///
    /// `Some(Duration::ZERO)` turns duplicate detection off: the first reply is credited
    /// at once, so a second joint at the same ID (a joint given a used ID, a replaced joint
    /// left at its factory ID) goes unnoticed, and whichever answer comes first is reported
    /// as the joint's value (another joint's position, status or register); its second
    /// answer then only counts as unmatched in the bus health. What it saves a caller that
    /// waits for each reply before its next request is that one frame and the allowance per
    /// request (about 0.07 ms per servo command on a memory bus); requests sent together
    /// ([`JointBus::request_many`]) hold their replies while the next ones are answered and
    /// save almost nothing.
    ///
    /// [`WhjError::DuplicateReply`]: crate::whj::WhjError::DuplicateReply
    /// [`FrameLink::reply_allowance`]: robobus_link::FrameLink::reply_allowance
    /// [`JointBus::request_many`]: crate::whj::JointBus::request_many
    pub collision_window: Option<Duration>,
    /// The longest one receive or sleep of the driving thread lasts before it looks at
    /// the session again and lets other threads in (default 0.5 ms).
    pub poll_interval: Duration,
    /// How the driving thread waits for replies and timed instants: in the kernel
    /// ([`WaitMode::Sleep`], the default), or polling from shortly before a reply can
    /// arrive (a request's wire time after it went out) or a timed instant (the cyclic
    /// loop's tick) until it comes ([`WaitMode::Spin`]: no thread wake-up on the reply's
    /// path, one core busy meanwhile). Replies are credited the same way in both.
    pub wait: WaitMode,
}

impl Default for JointBusConfig {
    fn default() -> Self {
        Self {
            reply_timeout: Duration::from_millis(20),
            retries: 2,
            connect_timeout: Duration::from_secs(5),
            verify_reads: false,
            step_limit_deg: 5.0,
            disable_settle: Duration::from_millis(5),
            save_settle: Duration::from_millis(50),
            bus_recovery_timeout: Duration::from_secs(1),
            error_passive_hold: Duration::from_secs(1),
            collision_window: None,
            poll_interval: Duration::from_micros(500),
            wait: WaitMode::Sleep,
        }
    }
}

impl JointBusConfig {
    /// Settings for simulated joints on the same machine (`robobus sim whj`, an in-process
    /// `robobus_sim::whj` bus): a 250 ms reply timeout and 5 retries instead of 20 ms and
    /// 2. The simulator is a thread or process that a loaded (or shared, virtual) machine
    /// can hold for hundreds of milliseconds; a real joint answers in about 0.2 ms.
    #[must_use]
    pub fn simulated() -> Self {
        Self {
            reply_timeout: Duration::from_millis(250),
            retries: 5,
            ..Self::default()
        }
    }
}

/// The CAN controller state as the client last saw it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum BusState {
    /// Error active: working normally.
    #[default]
    Active,
    /// Error warning (error counter ≥ 96): still working.
    ErrorWarning,
    /// Error passive (error counter ≥ 128): still working, many frames fail.
    ErrorPassive,
    /// Bus-off: the controller sends and receives nothing until it restarts.
    BusOff,
}

impl fmt::Display for BusState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Active => "active",
            Self::ErrorWarning => "error warning",
            Self::ErrorPassive => "error passive",
            Self::BusOff => "bus-off",
        })
    }
}
