//! The live loop with a recording allocates nothing per frame after warm-up. With a ring
//! (`mrsmap track --record-last`), on any thread: the loop copies each frame into a
//! slot, the writer thread keeps the last frames in reused buffers, and the file is
//! written at the end. With the whole run (`--record`), the writer thread compresses
//! and writes as frames come (and allocates for it, counted apart), the loop and the
//! tracker's workers allocate nothing. Both files read back. (One test in this binary:
//! the allocation counter is global.)

mod common;

use common::counting_alloc::{
    Counting, RECORDER_ALLOCATIONS, count_recorder_apart, first_allocation, start_counting, stop_counting,
};
use common::*;
use mrsmap::app::recorder::{RecordOptions, RecordStats};
use mrsmap::app::tracker_process::{LiveTracker, RunLimits, StopReason};
use mrsmap::io::recording::{RecordingReader, RecordingTopics};
use mrsmap::io::tracker_config::read_tracker_config;
use mrsmap::io::wire::RgbdFrameVga;
use std::path::Path;
use std::sync::atomic::Ordering;
use std::time::Duration;

#[global_allocator]
static GLOBAL: Counting = Counting;

const WARM_UP: u64 = 60;
const COUNTED: u64 = 300;

/// Runs the live loop with a recording (`last_seconds`: a ring, or `None`: the whole run)
/// on a thread of its own (a thread can start one `LiveTracker` only) and returns the
/// allocations counted in the frames after warm-up on every thread but the writer's, the
/// writer's own (when `writer_apart`), what was recorded and the folder holding the
/// file (`run.mcap`).
fn record_live(
    tag: &'static str,
    last_seconds: Option<f64>,
    writer_apart: bool,
) -> (usize, usize, RecordStats, TempDir) {
    std::thread::spawn(move || record_live_here(tag, last_seconds, writer_apart)).join().expect("the run completes")
}

fn record_live_here(tag: &str, last_seconds: Option<f64>, writer_apart: bool) -> (usize, usize, RecordStats, TempDir) {
    let dir = temp_dir(tag);
    let config_path = write_tracker_config(&dir, tag, "");
    let config = read_tracker_config(&config_path).expect("config");
    let mut tracker = LiveTracker::<RgbdFrameVga>::start(&config).expect("tracker starts");
    tracker
        .record(&RecordOptions { path: dir.join("run.mcap"), last_seconds, force: false })
        .expect("recording starts");
    let _camera = start_looping_driver(&config.camera_service, "100");
    let limits = RunLimits { max_frames: Some(WARM_UP + COUNTED), idle_timeout: Some(Duration::from_secs(30)) };
    count_recorder_apart(writer_apart);
    let summary = tracker
        .run(&limits, &mut |event| {
            if event.frames == WARM_UP {
                start_counting();
            }
            if event.frames == WARM_UP + COUNTED {
                stop_counting();
            }
        })
        .expect("loop runs");
    let allocations = stop_counting();
    let writer_allocations = RECORDER_ALLOCATIONS.load(Ordering::SeqCst);
    count_recorder_apart(false);
    let stats = tracker.finish_recording().expect("recording finishes").expect("a recording");
    println!("{tag}: {summary:?}\n{stats:?}\n{allocations} allocations, {writer_allocations} on the writer thread");
    assert_eq!(summary.stop, StopReason::FrameLimit, "the driver kept sending");
    (allocations, writer_allocations, stats, dir)
}

fn frames_in(path: &Path) -> u64 {
    let mut reader = RecordingReader::open(path, RecordingTopics::default(), None).expect("the recording opens");
    let mut frames = 0;
    while reader.next_frame().expect("frames decode").is_some() {
        frames += 1;
    }
    frames
}

#[test]
fn the_live_loop_with_a_recording_allocates_nothing_per_frame() {
    // A ring: nothing on any thread. A 0.1 s window holds 4 frames (sized for 30 Hz),
    // here the last 4 of a 100 Hz driver, whatever their stamps (the 8-frame clip loops,
    // its stamps jump back).
    let (allocations, _, stats, dir) = record_live("recloop-ring", Some(0.1), false);
    assert_eq!(
        allocations,
        0,
        "allocations in {COUNTED} frames with a ring recording; the first on {}",
        first_allocation()
    );
    assert!(stats.written >= 1 && stats.written <= 4, "the last 0.1 s: {stats:?}");
    assert_eq!(frames_in(&dir.join("run.mcap")), stats.written);
    // The whole run: the writer thread compresses and writes (and allocates for it);
    // the loop and the tracker's workers allocate nothing.
    let (allocations, writer_allocations, stats, dir) = record_live("recloop-whole", None, true);
    assert_eq!(
        allocations,
        0,
        "allocations off the writer thread in {COUNTED} frames, whole-run recording; the first on {}",
        first_allocation()
    );
    assert!(writer_allocations > 0, "the writer's allocations are counted apart, not lost");
    assert!(stats.written >= COUNTED, "the whole run: {stats:?}");
    assert_eq!(frames_in(&dir.join("run.mcap")), stats.written);
}
