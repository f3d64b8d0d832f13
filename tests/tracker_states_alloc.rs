//! The tracker step allocates nothing in any of its states with several objects:
//! tracking, an object lost while another stays tracked (its last pose carried along the
//! measured camera motion, the search around it refilled every frame), re-initialising
//! and found again; one object registered with the colour term, the other without;
//! each LM started from scratch and from the last frame's matches.
//! Counted on every thread (rayon workers included) by a global
//! allocator over a second pass of the same frames after `Tracker::reset`. (One test in
//! this binary: the allocation counter is global.)

mod common;

use common::counting_alloc::{Counting, first_allocation, start_counting, stop_counting};
use common::scenes::{TwoGroupsRun, blank};
use mrsmap::registration::ColorTerm;
use mrsmap::tracking::{PoseEstimate, SearchRegion, Tracker, TrackerParams, TrackingStatus};

#[global_allocator]
static GLOBAL: Counting = Counting;

const FRAMES: usize = 12;

/// One pass over the frames; the statuses of both objects per frame.
fn pass(
    tracker: &mut Tracker,
    scene: &TwoGroupsRun,
    first_stamp: usize,
    out: &mut [PoseEstimate; 2],
    statuses: &mut [[TrackingStatus; 2]; FRAMES],
) {
    for (k, status) in statuses.iter_mut().enumerate() {
        tracker.step(&scene.frame(k, ((first_stamp + k) * 33_000_000) as u64), out);
        *status = [out[0].status, out[1].status];
    }
}

#[test]
fn every_tracker_state_allocates_nothing_with_two_objects() {
    // With the paper's first association pass from scratch, and from the last matches.
    for start_from_last_matches in [false, true] {
        let mut params = TrackerParams::default();
        params.registration.start_from_last_matches = start_from_last_matches;
        allocates_nothing_with_two_objects(params);
    }
}

fn allocates_nothing_with_two_objects(params: TrackerParams) {
    let scene = TwoGroupsRun::new();
    assert_eq!(scene.targets.len(), FRAMES);
    let (mut left, right) = scene.models(SearchRegion { translation_m: 0.02, yaw_rad: 0.05 });
    left.color_term = Some(ColorTerm::default());
    let (width, height) = (scene.cam.width as usize, scene.cam.height as usize);
    let mut tracker = Tracker::new(params, width, height, vec![left, right]).expect("tracker");
    let mut out = [blank(), blank()];
    let mut warm_up = [[TrackingStatus::InvalidFrame; 2]; FRAMES];
    let mut counted = warm_up;
    // Inside a pool, as the tracker process runs the step (work injected into a pool
    // from a thread outside it allocates: docs/architecture.md).
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("pool");
    let allocations = pool.install(|| {
        pass(&mut tracker, &scene, 0, &mut out, &mut warm_up);
        tracker.reset();
        start_counting();
        pass(&mut tracker, &scene, FRAMES, &mut out, &mut counted);
        stop_counting()
    });
    let on = params.registration.start_from_last_matches;
    println!("start_from_last_matches {on}: warm-up: {warm_up:?}\ncounted: {counted:?}\n{allocations} allocations");
    let seen = |s: TrackingStatus| counted.iter().any(|f| f[1] == s);
    assert!(counted.iter().all(|f| f[0] == TrackingStatus::Tracking), "the left group stays tracked");
    assert!(
        seen(TrackingStatus::Lost)
            && seen(TrackingStatus::Initialising)
            && counted[FRAMES - 1][1] == TrackingStatus::Tracking,
        "the right group is tracked, lost, re-initialised and found again ({on}): {counted:?}"
    );
    assert_eq!(counted, warm_up, "the counted pass takes the warm-up's paths ({on})");
    assert_eq!(allocations, 0, "{allocations} heap allocations ({on}); the first on {}", first_allocation());
}
