//! The live tracker loop — iceoryx2 in, tracking, iceoryx2 out — allocates nothing per
//! frame after warm-up, over more than 1000 frames sent by a real camera-driver process.
//! (One test in this binary: the allocation counter is global.)

mod common;

use common::counting_alloc::{Counting, first_allocation, start_counting, stop_counting};
use common::*;
use mrsmap::app::tracker_process::{LiveTracker, RunLimits, StopReason};
use mrsmap::io::tracker_config::read_tracker_config;
use mrsmap::io::wire::RgbdFrameVga;
use std::time::Duration;

#[global_allocator]
static GLOBAL: Counting = Counting;

const WARM_UP: u64 = 50;
const COUNTED: u64 = 1000;

#[test]
fn the_live_loop_allocates_nothing_per_frame() {
    let dir = temp_dir("tracker-loop");
    let config_path = write_tracker_config(&dir, "loop", "");
    let config = read_tracker_config(&config_path).expect("config");
    let mut tracker = LiveTracker::<RgbdFrameVga>::start(&config).expect("tracker starts");
    let _camera = start_looping_driver(&config.camera_service, "300");
    let mut counted_frames = 0;
    let mut tracking = 0;
    let limits = RunLimits { max_frames: Some(WARM_UP + COUNTED), idle_timeout: Some(Duration::from_secs(30)) };
    let summary = tracker
        .run(&limits, &mut |event| {
            if event.frames == WARM_UP {
                start_counting();
            } else if event.frames > WARM_UP {
                counted_frames += 1;
                tracking += usize::from(event.output.estimates[0].status == mrsmap::tracking::TrackingStatus::Tracking);
            }
            if event.frames == WARM_UP + COUNTED {
                stop_counting();
            }
        })
        .expect("loop runs");
    let allocations = stop_counting();
    println!("{summary:?}\n{counted_frames} frames counted, {tracking} tracking, {allocations} allocations");
    assert_eq!(summary.stop, StopReason::FrameLimit, "the driver kept sending");
    assert_eq!(counted_frames, COUNTED);
    assert!(tracking > 0, "the teddy was tracked in some frames");
    assert_eq!(
        allocations,
        0,
        "{allocations} heap allocations in {COUNTED} frames of the live loop; the first on {}",
        first_allocation()
    );
}
