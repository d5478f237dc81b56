//! What every fuzz target shares: an allocator that reports to the allocation-bound check,
//! and the macro that makes a target of a property of `robobus-fuzzing`.

use std::alloc::{GlobalAlloc, Layout, System};

pub use libfuzzer_sys;

/// The system allocator, reporting every allocation to `robobus_fuzzing::alloc`.
pub struct Counting;

// SAFETY: every call goes to `System` unchanged; the reports are plain arithmetic on
// atomics and allocate nothing.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's layout, forwarded.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            robobus_fuzzing::alloc::on_alloc(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: a pointer this allocator returned, with its layout.
        unsafe { System.dealloc(ptr, layout) };
        robobus_fuzzing::alloc::on_dealloc(layout.size());
    }
}

/// `target!(name)`: a fuzz target that checks `robobus_fuzzing::name` on every input,
/// within the allocation bound; a violation is a crash libFuzzer keeps.
#[macro_export]
macro_rules! target {
    ($name:ident) => {
        #[global_allocator]
        static ALLOC: $crate::Counting = $crate::Counting;

        $crate::libfuzzer_sys::fuzz_target!(|data: &[u8]| {
            if let Err(v) = robobus_fuzzing::alloc::check_bounded(data, robobus_fuzzing::$name) {
                panic!("{}: {v}", stringify!($name));
            }
        });
    };
}
