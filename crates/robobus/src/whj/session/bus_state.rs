//! The bus-error state: bus-off, error-passive and error-warning as the link reports them,
//! the hold after which an error-passive bus counts as active again, and the bus health's
//! counters and last error.

use std::time::Instant;

use robobus_link::{BusErrorKind, FrameLinkError};

use super::{BusState, Session};

impl Session {
    pub(super) const fn state(&self) -> BusState {
        self.telemetry.bus.state
    }

    pub(super) fn set_state(&mut self, state: BusState, detail: Option<String>) {
        let bus = self.health();
        let was = bus.state;
        if was != state && state == BusState::Active {
            bus.recoveries += 1;
            tracing::info!(from = %was, "CAN bus recovered");
        }
        bus.state = state;
        if let Some(d) = detail {
            bus.last_error = Some(d);
        }
    }

    pub(super) fn recover_passive(&mut self, now: Instant) {
        if let Some(since) = self.passive_since
            && now.saturating_duration_since(since) >= self.config.error_passive_hold
        {
            self.passive_since = None;
            if matches!(
                self.state(),
                BusState::ErrorPassive | BusState::ErrorWarning
            ) {
                self.set_state(BusState::Active, None);
            }
        }
    }

    pub(super) fn last_error(&self) -> String {
        self.telemetry
            .bus
            .last_error
            .clone()
            .unwrap_or_else(|| "no detail".into())
    }

    /// Applies a bus error reported at `now` to the state.
    pub(super) fn link_error_state(&mut self, e: &FrameLinkError, now: Instant) {
        let detail = Some(e.to_string());
        let state = self.state();
        match e {
            FrameLinkError::BusOff { .. } => {
                self.health().bus_off_events += 1;
                tracing::warn!(error = %e, "CAN bus-off");
                self.set_state(BusState::BusOff, detail);
            }
            FrameLinkError::ErrorPassive { .. } => {
                self.health().error_passive_events += 1;
                self.passive_since = Some(now);
                if state != BusState::BusOff {
                    self.set_state(BusState::ErrorPassive, detail);
                }
            }
            FrameLinkError::BusError { kind, .. } => {
                self.health().other_bus_errors += 1;
                match kind {
                    BusErrorKind::Restarted => self.set_state(BusState::Active, detail),
                    BusErrorKind::BusOff => self.set_state(BusState::BusOff, detail),
                    BusErrorKind::ErrorPassive => {
                        self.passive_since = Some(now);
                        if state != BusState::BusOff {
                            self.set_state(BusState::ErrorPassive, detail);
                        }
                    }
                    BusErrorKind::ErrorWarning => {
                        self.passive_since = Some(now);
                        if state == BusState::Active {
                            self.set_state(BusState::ErrorWarning, detail);
                        }
                    }
                    BusErrorKind::NoAck | BusErrorKind::Other { .. } => {
                        self.health().last_error = detail;
                    }
                }
            }
            _ => self.health().last_error = detail,
        }
    }
}
