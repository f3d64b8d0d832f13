//! A global allocator that counts allocations on every thread while armed (tests that
//! prove a loop allocates nothing install it with `#[global_allocator]`). Allocations of
//! the recording's writer thread can be counted apart ([`count_recorder_apart`]).
//!
//! The test harness's own thread is not counted when the test runs on another one
//! (libtest's default): it allocates by itself, e.g. to note a test that has run for
//! more than 60 s, which a loaded machine can make the live-loop tests do. The first
//! counted allocation's thread and backtrace are kept for the failure message
//! ([`first_allocation`]).
//!
//! A thread named `test-detector` is never counted: it plays an external detector that
//! sends detections to the tracker under test, a process of its own in real use.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// The name of the recording's writer thread (`app::recorder`).
const RECORDER_THREAD: &str = "mrsmap-recorder";

/// The name of the test harness's thread (the process's main thread).
const HARNESS_THREAD: &str = "main";

/// The name of a test's stand-in for an external detector process (never counted).
pub const DETECTOR_THREAD: &str = "test-detector";

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

/// Whether the harness's thread is left out (the counting test runs on another one).
static HARNESS_APART: AtomicBool = AtomicBool::new(false);

/// What a thread is, for counting.
#[derive(Clone, Copy, PartialEq)]
enum Kind {
    /// Not found out yet.
    Unknown,
    /// Being found out (an allocation meanwhile counts as [`Kind::Other`]'s: the error
    /// is on the safe side).
    Classifying,
    /// The recording's writer.
    Recorder,
    /// The test harness's thread.
    Harness,
    /// A stand-in for another process ([`DETECTOR_THREAD`]).
    Detector,
    /// Any other thread: the code under test.
    Other,
}

thread_local! {
    /// What the current thread is, found on its first counted allocation.
    static THREAD_KIND: Cell<Kind> = const { Cell::new(Kind::Unknown) };
    /// Set while this thread captures a backtrace (whose own allocations are not counted).
    static CAPTURING: Cell<bool> = const { Cell::new(false) };
}

/// What the current thread is.
fn thread_kind() -> Kind {
    THREAD_KIND
        .try_with(|kind| match kind.get() {
            Kind::Unknown => {
                kind.set(Kind::Classifying);
                let found = match std::thread::current().name() {
                    Some(RECORDER_THREAD) => Kind::Recorder,
                    Some(HARNESS_THREAD) => Kind::Harness,
                    Some(DETECTOR_THREAD) => Kind::Detector,
                    _ => Kind::Other,
                };
                kind.set(found);
                found
            }
            Kind::Classifying => Kind::Other,
            k => k,
        })
        .unwrap_or(Kind::Other)
}

/// Where the first counted allocation since [`start_counting`] came from.
static FIRST: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);

fn count() {
    if !ARMED.load(Ordering::Relaxed) || CAPTURING.try_with(Cell::get).unwrap_or(true) {
        return;
    }
    match thread_kind() {
        Kind::Harness if HARNESS_APART.load(Ordering::Relaxed) => {}
        Kind::Detector => {}
        Kind::Recorder if RECORDER_APART.load(Ordering::Relaxed) => {
            RECORDER_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        _ => {
            if ALLOCATIONS.fetch_add(1, Ordering::Relaxed) == 0 {
                remember_first();
            }
        }
    }
}

/// Keeps the thread and backtrace of the first counted allocation.
fn remember_first() {
    let _ = CAPTURING.try_with(|c| c.set(true));
    let thread = std::thread::current().name().unwrap_or("unnamed").to_string();
    let trace = std::backtrace::Backtrace::force_capture();
    if let Ok(mut first) = FIRST.lock() {
        *first = Some(format!("thread {thread}:\n{trace}"));
    }
    let _ = CAPTURING.try_with(|c| c.set(false));
}

/// The thread and backtrace of the first allocation counted since [`start_counting`]
/// (empty if there was none).
pub fn first_allocation() -> String {
    FIRST.lock().map(|f| f.clone().unwrap_or_default()).unwrap_or_default()
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

/// Resets the count and starts counting: on every thread but the harness's, unless the
/// caller is on the harness's thread itself (the test then runs there).
pub fn start_counting() {
    let caller_is_harness = std::thread::current().name() == Some(HARNESS_THREAD);
    HARNESS_APART.store(!caller_is_harness, Ordering::SeqCst);
    if let Ok(mut first) = FIRST.lock() {
        *first = None;
    }
    ALLOCATIONS.store(0, Ordering::SeqCst);
    ARMED.store(true, Ordering::SeqCst);
}

/// Stops counting and returns the allocations counted since [`start_counting`].
pub fn stop_counting() -> usize {
    ARMED.store(false, Ordering::SeqCst);
    ALLOCATIONS.load(Ordering::SeqCst)
}
