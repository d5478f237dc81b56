//! Allocation bounds: counters of the bytes live and their peak, and the check against them.
//!
//! The fuzz binaries install a global allocator (`fuzz/src/lib.rs`) that reports every
//! allocation here ([`on_alloc`], [`on_dealloc`]); [`check_bounded`] runs a check and fails
//! when the bytes live at once grew by more than [`PER_INPUT_BYTE`] times the input's
//! length plus [`BASELINE`]. (This crate forbids `unsafe`, which an allocator needs: the
//! allocator lives with the fuzz targets, the arithmetic here.)

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use crate::{Checked, Violation};

/// Bytes a check may hold at once per byte of input.
pub const PER_INPUT_BYTE: usize = 64;

/// Bytes a check may hold at once whatever its input (buffers of fixed size).
pub const BASELINE: usize = 1 << 20;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static COUNTING: AtomicBool = AtomicBool::new(false);

/// An allocation of `size` bytes was made.
pub fn on_alloc(size: usize) {
    COUNTING.store(true, Ordering::Relaxed);
    let live = LIVE.fetch_add(size, Ordering::Relaxed).saturating_add(size);
    PEAK.fetch_max(live, Ordering::Relaxed);
}

/// An allocation of `size` bytes was freed.
pub fn on_dealloc(size: usize) {
    let _ = LIVE.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |l| {
        Some(l.saturating_sub(size))
    });
}

/// Runs `check` on `input` and fails if, while it ran, the bytes live grew beyond the
/// bound. Where nothing reports allocations it only runs the check. Single-threaded
/// callers only (a fuzz target): another thread's allocations would count too.
pub fn check_bounded(input: &[u8], check: impl FnOnce(&[u8]) -> Checked) -> Checked {
    let before = LIVE.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    check(input)?;
    if !COUNTING.load(Ordering::Relaxed) {
        return Ok(());
    }
    let grew = PEAK.load(Ordering::Relaxed).saturating_sub(before);
    let bound = input
        .len()
        .saturating_mul(PER_INPUT_BYTE)
        .saturating_add(BASELINE);
    if grew > bound {
        return Err(Violation(format!(
            "{grew} bytes allocated at once for {} bytes of input (bound {bound})",
            input.len()
        )));
    }
    Ok(())
}
