//! The live tracker loop — iceoryx2 in, tracking, iceoryx2 out — allocates nothing per
//! frame after warm-up, over more than 1000 frames sent by a real camera-driver process,
//! while a detector sends detections that the tracker takes and applies, and a second
//! object, configured where nothing is, is never found: every frame it is registered
//! from its configured poses in turn, while its carried pose follows the camera motion
//! the teddy measures (`Tracker::end_frame`). (One test in
//! this binary: the allocation counter is global.)

mod common;

use common::counting_alloc::{Counting, DETECTOR_THREAD, first_allocation, start_counting, stop_counting};
use common::*;
use mrsmap::app::tracker_process::{LiveTracker, RunLimits, StopReason};
use mrsmap::io::ipc;
use mrsmap::io::tracker_config::read_tracker_config;
use mrsmap::io::wire::{ObjectDetection, RgbdFrameVga, detection_mode};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

#[global_allocator]
static GLOBAL: Counting = Counting;

const WARM_UP: u64 = 50;
const COUNTED: u64 = 1000;

#[test]
fn the_live_loop_allocates_nothing_per_frame() {
    let dir = temp_dir("tracker-loop");
    // The second object: the teddy's model half a metre to the left of the teddy, where
    // the clip shows the table's edge and no teddy.
    let second = format!(
        "[[object]]\nname = \"absent\"\nmodel = \"{}\"\n\
         camera_from_object = [-0.3077, 0.1253, 1.0402, -0.25098, -0.79599, 0.53327, -0.13797]\n",
        root().join("models/teddy.mrsm").display()
    );
    let config_path = dir.join("tracker.toml");
    std::fs::write(&config_path, tracker_config_text("loop", "") + &second).expect("write config");
    let config = read_tracker_config(&config_path).expect("config");
    let mut tracker = LiveTracker::<RgbdFrameVga>::start(&config).expect("tracker starts");
    let _camera = start_looping_driver(&config.camera_service, "300");
    // A detector (another process in real use: its thread is not counted) sends the
    // teddy's pose in the clip's first frame every 40 ms, alternately "when not
    // tracking" and "always".
    let stop = Arc::new(AtomicBool::new(false));
    let detector = {
        let (stop, service, pose) =
            (stop.clone(), config.detections_service.clone(), config.objects[0].camera_from_object);
        std::thread::Builder::new()
            .name(DETECTOR_THREAD.into())
            .spawn(move || {
                let node = ipc::node("test_detector").expect("node");
                let publisher = ipc::detections(&node, &service).expect("service").publisher_builder().create();
                let publisher = publisher.expect("publisher");
                let mut sent = 0u32;
                while !stop.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(40));
                    let mode =
                        if sent.is_multiple_of(2) { detection_mode::WHEN_NOT_TRACKING } else { detection_mode::ALWAYS };
                    publisher.send_copy(ObjectDetection::new("teddy", &pose, 0, mode)).expect("sent");
                    sent += 1;
                }
                sent
            })
            .expect("detector thread")
    };
    let mut counted_frames = 0;
    let mut tracking = 0;
    let mut absent_tracking = 0;
    let limits = RunLimits { max_frames: Some(WARM_UP + COUNTED), idle_timeout: Some(Duration::from_secs(30)) };
    let summary = tracker
        .run(&limits, &mut |event| {
            if event.frames == WARM_UP {
                start_counting();
            } else if event.frames > WARM_UP {
                counted_frames += 1;
                let is_tracking =
                    |k: usize| event.output.estimates[k].status == mrsmap::tracking::TrackingStatus::Tracking;
                tracking += usize::from(is_tracking(0));
                absent_tracking += usize::from(is_tracking(1));
            }
            if event.frames == WARM_UP + COUNTED {
                stop_counting();
            }
        })
        .expect("loop runs");
    let allocations = stop_counting();
    stop.store(true, Ordering::Relaxed);
    let sent = detector.join().expect("detector");
    let d = summary.detections;
    println!("{sent} detections sent: {d:?}");
    assert!(d.applied > 0 && d.not_needed > 0 && d.invalid + d.stale + d.unknown_object == 0, "{d:?}");
    println!(
        "{} frames ({} skipped as stale), stop {:?}\n{counted_frames} frames counted, {tracking} tracking the teddy, {absent_tracking} the absent \
         object, {allocations} allocations",
        summary.frames, summary.skipped_frames, summary.stop
    );
    assert_eq!(summary.stop, StopReason::FrameLimit, "the driver kept sending");
    assert_eq!(counted_frames, COUNTED);
    assert!(tracking > 0, "the teddy was tracked in some frames");
    assert!(absent_tracking < COUNTED as usize / 10, "the absent object was mostly lost: {absent_tracking}");
    assert_eq!(
        allocations,
        0,
        "{allocations} heap allocations in {COUNTED} frames of the live loop; the first on {}",
        first_allocation()
    );
}
