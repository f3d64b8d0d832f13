//! The tracker step allocates nothing in any of its states with several objects:
//! tracking, an object lost while another stays tracked (its last pose carried along the
//! measured camera motion, the search around it refilled every frame), re-initialising
//! and found again. Counted on every thread (rayon workers included) by a global
//! allocator over a second pass of the same frames after `Tracker::reset`. (One test in
//! this binary: the allocation counter is global.)

mod common;

use common::counting_alloc::{Counting, first_allocation, start_counting, stop_counting};
use common::scenes::{blank, object_model_in, two_groups};
use common::*;
use mrsmap::frame::RgbdFrame;
use mrsmap::geometry::Pose;
use mrsmap::geometry::se3::left_increment;
use mrsmap::synthetic::RenderTarget;
use mrsmap::tracking::{ObjectModel, PoseEstimate, SearchRegion, Tracker, TrackerParams, TrackingStatus};
use nalgebra::{Vector3, Vector6};

#[global_allocator]
static GLOBAL: Counting = Counting;

const FRAMES: usize = 12;

/// One pass over the frames; the statuses of both objects per frame.
fn pass(
    tracker: &mut Tracker,
    frames: &[RgbdFrame],
    first_stamp: usize,
    out: &mut [PoseEstimate; 2],
    statuses: &mut [[TrackingStatus; 2]; FRAMES],
) {
    for (k, frame) in frames.iter().enumerate() {
        let frame = RgbdFrame { stamp_ns: ((first_stamp + k) * 33_000_000) as u64, ..*frame };
        tracker.step(&frame, out);
        statuses[k] = [out[0].status, out[1].status];
    }
}

#[test]
fn every_tracker_state_allocates_nothing_with_two_objects() {
    let mesh = two_groups();
    let cam = vga().halved();
    let poses: Vec<Pose> =
        (0..FRAMES).map(|k| left_increment(&(Vector6::new(0.0, -0.002, 0.012, 0.0, 0.002, 0.0) * k as f64))).collect();
    let targets: Vec<RenderTarget> = poses.iter().map(|p| render_frame(&mesh, cam, p)).collect();
    let views = [(&targets[0], poses[0]), (&targets[FRAMES - 1], poses[FRAMES - 1])];
    let (y, z) = ((0.335, 0.155), (0.88, 0.22));
    let group = |x: f64, name: &str| {
        let center = Vector3::new(x, y.0, z.0);
        ObjectModel {
            name: name.into(),
            search: SearchRegion { translation_m: 0.02, yaw_rad: 0.05 },
            ..object_model_in(&views, center, Vector3::new(0.235, y.1, z.1), center)
        }
    };
    // The right group is hidden (no depth right of the gap between the groups) in
    // frames 4-9.
    let depths: Vec<Vec<u16>> = targets
        .iter()
        .enumerate()
        .map(|(k, t)| {
            let mut depth = t.depth.clone();
            if (4..10).contains(&k) {
                for (i, d) in depth.iter_mut().enumerate() {
                    if i % cam.width as usize >= 160 {
                        *d = 0;
                    }
                }
            }
            depth
        })
        .collect();
    let frames: Vec<RgbdFrame> =
        targets.iter().zip(&depths).map(|(t, depth)| RgbdFrame::new(0, cam, &t.rgb, depth).expect("frame")).collect();
    let models = vec![group(-0.235, "left"), group(0.235, "right")];
    let mut tracker =
        Tracker::new(TrackerParams::default(), cam.width as usize, cam.height as usize, models).expect("tracker");
    let mut out = [blank(), blank()];
    let mut warm_up = [[TrackingStatus::InvalidFrame; 2]; FRAMES];
    let mut counted = warm_up;
    // Inside a pool, as the tracker process runs the step (work injected into a pool
    // from a thread outside it allocates: docs/architecture.md).
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("pool");
    let allocations = pool.install(|| {
        pass(&mut tracker, &frames, 0, &mut out, &mut warm_up);
        tracker.reset();
        start_counting();
        pass(&mut tracker, &frames, FRAMES, &mut out, &mut counted);
        stop_counting()
    });
    println!("warm-up: {warm_up:?}\ncounted: {counted:?}\n{allocations} allocations");
    let seen = |s: TrackingStatus| counted.iter().any(|f| f[1] == s);
    assert!(counted.iter().all(|f| f[0] == TrackingStatus::Tracking), "the left group stays tracked");
    assert!(
        seen(TrackingStatus::Lost)
            && seen(TrackingStatus::Initialising)
            && counted[FRAMES - 1][1] == TrackingStatus::Tracking,
        "the right group is tracked, lost, re-initialised and found again: {counted:?}"
    );
    assert_eq!(counted, warm_up, "the counted pass takes the warm-up's paths");
    assert_eq!(allocations, 0, "{allocations} heap allocations; the first on {}", first_allocation());
}
