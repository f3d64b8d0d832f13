//! The live loop with a ring recording (`mrsmap track --record-last`) allocates nothing
//! per frame after warm-up, on any thread: the loop copies each frame into a slot, the
//! writer thread keeps the last frames in reused buffers. The file is written at the end
//! and reads back. (One test in this binary: the allocation counter is global.)

mod common;

use common::counting_alloc::{Counting, start_counting, stop_counting};
use common::*;
use mrsmap::app::recorder::RecordOptions;
use mrsmap::app::tracker_process::{LiveTracker, RunLimits, StopReason};
use mrsmap::io::recording::{RecordingReader, RecordingTopics};
use mrsmap::io::tracker_config::read_tracker_config;
use mrsmap::io::wire::RgbdFrameVga;
use std::time::Duration;

#[global_allocator]
static GLOBAL: Counting = Counting;

const WARM_UP: u64 = 60;
const COUNTED: u64 = 300;

#[test]
fn the_live_loop_with_a_ring_recording_allocates_nothing_per_frame() {
    let dir = temp_dir("recorder-loop");
    let config_path = write_tracker_config(&dir, "recloop", "");
    let config = read_tracker_config(&config_path).expect("config");
    let mut tracker = LiveTracker::<RgbdFrameVga>::start(&config).expect("tracker starts");
    let path = dir.join("ring.mcap");
    // The clip spans 0.23 s and loops (its stamps jump back): a 0.1 s window.
    tracker.record(&RecordOptions { path: path.clone(), last_seconds: Some(0.1) }).expect("recording starts");
    let _camera = start_looping_driver(&config.camera_service, "100");
    let limits = RunLimits { max_frames: Some(WARM_UP + COUNTED), idle_timeout: Some(Duration::from_secs(30)) };
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
    let stats = tracker.finish_recording().expect("recording finishes").expect("a recording");
    println!("{summary:?}\n{stats:?}\n{allocations} allocations");
    assert_eq!(summary.stop, StopReason::FrameLimit, "the driver kept sending");
    assert_eq!(allocations, 0, "allocations in {COUNTED} frames with a ring recording");
    assert!(stats.written >= 1 && stats.written <= 8, "the last 0.1 s: {stats:?}");
    let mut reader = RecordingReader::open(&path, RecordingTopics::default(), None).expect("the recording opens");
    let mut frames = 0;
    while reader.next_frame().expect("frames decode").is_some() {
        frames += 1;
    }
    assert_eq!(frames as u64, stats.written);
}
