//! The one Ctrl-C / SIGTERM handler of the `robobus` command (on Windows: Ctrl-C,
//! Ctrl-Break and closing the console window, through the same `ctrlc` handler).
//!
//! [`stop_token`] installs it on first use: from then on a signal sets the shared
//! [`StopToken`] instead of killing the process, so the running library operation brings
//! its devices to their safe state and returns `Interrupted` (exit code 130).

use std::sync::OnceLock;

use robobus::ops::StopToken;

/// The process's stop token, set by Ctrl-C / SIGTERM (the handler is installed once).
pub(crate) fn stop_token() -> StopToken {
    static TOKEN: OnceLock<StopToken> = OnceLock::new();
    TOKEN
        .get_or_init(|| {
            let token = StopToken::new();
            let flag = token.clone();
            if let Err(e) = ctrlc::set_handler(move || flag.stop()) {
                tracing::warn!("cannot install the Ctrl-C handler: {e}");
            }
            token
        })
        .clone()
}
