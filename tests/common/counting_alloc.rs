//! A global allocator that counts allocations on every thread while armed (tests that
//! prove a loop allocates nothing install it with `#[global_allocator]`). Allocations of
//! the recording's writer thread can be counted apart ([`count_recorder_apart`]).
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// The name of the recording's writer thread (`app::recorder`).
const RECORDER_THREAD: &str = "mrsmap-recorder";

/// Counts allocations and reallocations while [`ARMED`].
pub struct Counting;

/// Whether allocations are counted.
pub static ARMED: AtomicBool = AtomicBool::new(false);
/// Allocations counted.
pub static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

/// Whether the writer thread's allocations go to [`RECORDER_ALLOCATIONS`].
static RECORDER_APART: AtomicBool = AtomicBool::new(false);
/// Allocations of the writer thread, when counted apart.
pub static RECORDER_ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

const UNKNOWN: u8 = 0;
const OTHER: u8 = 1;
const RECORDER: u8 = 2;
const CLASSIFYING: u8 = 3;

thread_local! {
    /// What the current thread is, found on its first counted allocation.
    static THREAD_KIND: Cell<u8> = const { Cell::new(UNKNOWN) };
}

/// Whether the current thread is the recording's writer. An allocation made while
/// finding out (re-entrant) counts as another thread's: the error is on the safe side.
fn on_recorder_thread() -> bool {
    THREAD_KIND
        .try_with(|kind| match kind.get() {
            UNKNOWN => {
                kind.set(CLASSIFYING);
                let recorder = std::thread::current().name() == Some(RECORDER_THREAD);
                kind.set(if recorder { RECORDER } else { OTHER });
                recorder
            }
            k => k == RECORDER,
        })
        .unwrap_or(false)
}

fn count() {
    if ARMED.load(Ordering::Relaxed) {
        if RECORDER_APART.load(Ordering::Relaxed) && on_recorder_thread() {
            RECORDER_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        } else {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
    }
}

// SAFETY: forwards every call to the system allocator unchanged; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// From now on, allocations of the recording's writer thread are counted in
/// [`RECORDER_ALLOCATIONS`], not in the total [`stop_counting`] returns.
pub fn count_recorder_apart(apart: bool) {
    RECORDER_ALLOCATIONS.store(0, Ordering::SeqCst);
    RECORDER_APART.store(apart, Ordering::SeqCst);
}

/// Resets the count and starts counting.
pub fn start_counting() {
    ALLOCATIONS.store(0, Ordering::SeqCst);
    ARMED.store(true, Ordering::SeqCst);
}

/// Stops counting and returns the allocations counted since [`start_counting`].
pub fn stop_counting() -> usize {
    ARMED.store(false, Ordering::SeqCst);
    ALLOCATIONS.load(Ordering::SeqCst)
}
