//! Object tracking on rendered frames with known poses: accuracy, loss when the object
//! leaves the view, re-initialisation when it comes back, invalid frames.

mod common;

use common::scenes::{TwoGroupsRun, blank, object_model_in};
use common::*;
use mrsmap::frame::RgbdFrame;
use mrsmap::geometry::Pose;
use mrsmap::geometry::se3::left_increment;
use mrsmap::synthetic::{RenderTarget, room};
use mrsmap::tracking::{
    FreeSpaceProbe, ObjectModel, PoseEstimate, SearchRegion, Tracker, TrackerParams, TrackingStatus,
};
use nalgebra::{Translation3, UnitQuaternion, Vector3, Vector6};

/// The "object": the two boxes and the sphere on the table of `room(5)`, fused from
/// `views` at their known poses (object frame = the first camera's frame), inside a box
/// above the table — a model as the mapping tool makes it, from several key views.
fn object_model(views: &[(&RenderTarget, Pose)]) -> ObjectModel {
    object_model_in(views, Vector3::new(-0.1, 0.24, 0.98), Vector3::new(0.45, 0.25, 0.3), Vector3::zeros())
}

fn frame(t: &RenderTarget, k: u64) -> RgbdFrame<'_> {
    RgbdFrame::new(k * 33_000_000, t.camera, &t.rgb, &t.depth).expect("rendered frame")
}

fn step(tracker: &mut Tracker, t: &RenderTarget, k: u64) -> PoseEstimate {
    let mut out = [PoseEstimate { ..blank() }];
    tracker.step(&frame(t, k), &mut out);
    out[0]
}

#[test]
fn tracks_loses_and_reinitialises() {
    tracks_loses_and_reinitialises_with(TrackerParams::default());
}

#[test]
fn tracks_loses_and_reinitialises_starting_each_frame_from_scratch() {
    let mut params = TrackerParams::default();
    params.registration.start_from_last_matches = false;
    tracks_loses_and_reinitialises_with(params);
}

fn tracks_loses_and_reinitialises_with(params: TrackerParams) {
    let mesh = room(5);
    let cam = vga();
    // The camera moves 7 mm and 0.2° per frame (object frame = first camera frame); the
    // objects are small (12–40 cm): a few hundred surfel associations per frame.
    let poses: Vec<Pose> =
        (0..12).map(|k| left_increment(&(Vector6::new(0.006, -0.002, 0.004, 0.001, 0.003, 0.0) * k as f64))).collect();
    let frames: Vec<RenderTarget> = poses.iter().map(|p| render_frame(&mesh, cam, p)).collect();
    let views = [(&frames[0], poses[0]), (&frames[6], poses[6]), (&frames[11], poses[11])];
    let mut tracker =
        Tracker::new(params, cam.width as usize, cam.height as usize, vec![object_model(&views)]).expect("tracker");
    let mut last_good = Pose::identity();
    for (k, (t, truth)) in frames.iter().zip(&poses).enumerate() {
        let e = step(&mut tracker, t, k as u64);
        last_good = e.camera_from_object;
        let (mm, deg) = pose_error(&e.camera_from_object.inverse(), truth);
        println!(
            "frame {k}: {:?} quality {:.2} free space {:.3} error {:.2} mm {:.3}° assoc {} it {}",
            e.status,
            e.quality,
            e.free_space,
            mm * 1e3,
            deg,
            e.associations,
            e.iterations
        );
        assert_eq!(e.status, TrackingStatus::Tracking, "frame {k}");
        assert!(e.is_fresh(), "frame {k}: estimated from its frame");
        assert!(mm < 2e-3 && deg < 0.25, "frame {k}: {:.2} mm {:.3}°", mm * 1e3, deg);
        assert!(e.quality > 0.8, "a good fit has quality near 1: {}", e.quality);
        assert!(e.free_space < 0.02, "the depth image does not see through a good fit: {}", e.free_space);
        assert!(e.covariance_ros[(0, 0)] > 0.0 && e.covariance_ros[(0, 0)] < 1e-4);
    }
    // The camera turns away: no overlap. Held twice, lost at the third frame.
    let away = render_frame(&mesh, cam, &left_increment(&Vector6::new(0.0, 0.0, 0.0, 0.0, 2.4, 0.0)));
    let first = step(&mut tracker, &away, 20);
    let held: Vec<PoseEstimate> = (21..24).map(|k| step(&mut tracker, &away, k)).collect();
    let statuses: Vec<TrackingStatus> = held.iter().map(|e| e.status).collect();
    assert_eq!(statuses, [TrackingStatus::Tracking, TrackingStatus::Lost, TrackingStatus::Initialising]);
    assert_eq!(first.camera_from_object, last_good, "the pose is held while registrations fail");
    // Held poses are tracking but not estimated from their frame: trajectories leave
    // them out.
    assert_eq!((first.status, first.bad_frames, first.is_fresh()), (TrackingStatus::Tracking, 1, false));
    assert_eq!((held[0].bad_frames, held[0].is_fresh()), (2, false));
    assert_eq!(first.covariance_ros, nalgebra::Matrix6::identity(), "a held pose has no covariance of its own");
    // Back near the initial view: a re-initialisation hypothesis catches it.
    let back = render_frame(&mesh, cam, &poses[1]);
    let mut status = TrackingStatus::Initialising;
    for k in 30..45 {
        status = step(&mut tracker, &back, k).status;
        if status == TrackingStatus::Tracking {
            break;
        }
    }
    assert_eq!(status, TrackingStatus::Tracking, "re-initialised from the hypotheses");
    let e = step(&mut tracker, &back, 50);
    let (mm, _) = pose_error(&e.camera_from_object.inverse(), &poses[1]);
    assert!(mm < 2e-3, "{:.2} mm after re-initialisation", mm * 1e3);
}

#[test]
fn an_unusable_frame_leaves_the_state_alone() {
    let mesh = room(5);
    let cam = vga().halved();
    let first = render_frame(&mesh, cam, &Pose::identity());
    let mut tracker = Tracker::new(
        TrackerParams::default(),
        cam.width as usize,
        cam.height as usize,
        vec![object_model(&[(&first, Pose::identity())])],
    )
    .expect("tracker");
    assert_eq!(step(&mut tracker, &first, 0).status, TrackingStatus::Tracking);
    let e = tracker.invalid_frame(0, 1);
    assert_eq!(e.status, TrackingStatus::InvalidFrame);
    assert_eq!(step(&mut tracker, &first, 2).status, TrackingStatus::Tracking);
}

#[test]
fn several_objects_are_tracked_in_one_step() {
    let mesh = room(5);
    let cam = vga().halved();
    let first = render_frame(&mesh, cam, &Pose::identity());
    let mut second = object_model(&[(&first, Pose::identity())]);
    second.name = "objects-again".into();
    let models = vec![object_model(&[(&first, Pose::identity())]), second];
    let mut tracker =
        Tracker::new(TrackerParams::default(), cam.width as usize, cam.height as usize, models).expect("tracker");
    assert_eq!(tracker.names(), ["objects", "objects-again"]);
    let moved = left_increment(&Vector6::new(0.006, -0.002, 0.004, 0.001, 0.003, 0.0));
    let next = render_frame(&mesh, cam, &moved);
    let mut out = [blank(), blank()];
    tracker.step(&frame(&first, 0), &mut out);
    tracker.step(&frame(&next, 1), &mut out);
    for (k, e) in out.iter().enumerate() {
        assert_eq!((e.object, e.status), (k, TrackingStatus::Tracking));
        let (mm, _) = pose_error(&e.camera_from_object.inverse(), &moved);
        assert!(mm < 2e-3, "object {k}: {:.2} mm", mm * 1e3);
    }
}

#[test]
fn the_published_covariance_is_scaled_as_configured() {
    let mesh = room(5);
    let cam = vga().halved();
    let first = render_frame(&mesh, cam, &Pose::identity());
    let next = render_frame(&mesh, cam, &left_increment(&Vector6::new(0.006, -0.002, 0.004, 0.001, 0.003, 0.0)));
    let run = |covariance_scale: f64| {
        let params = TrackerParams { covariance_scale, ..TrackerParams::default() };
        let model = object_model(&[(&first, Pose::identity())]);
        let mut tracker = Tracker::new(params, cam.width as usize, cam.height as usize, vec![model]).expect("tracker");
        step(&mut tracker, &first, 0);
        step(&mut tracker, &next, 1)
    };
    let (plain, wide) = (run(1.0), run(100.0));
    assert!(plain.is_fresh() && wide.is_fresh());
    assert_eq!(plain.camera_from_object, wide.camera_from_object, "the pose does not depend on the scale");
    assert!(plain.covariance_ros[(0, 0)] > 0.0);
    assert_eq!(wide.covariance_ros, plain.covariance_ros * 100.0);
    let refused = TrackerParams { covariance_scale: 0.0, ..TrackerParams::default() };
    let err = Tracker::new(refused, cam.width as usize, cam.height as usize, vec![]).unwrap_err();
    assert!(err.to_string().contains("covariance_scale"), "{err}");
}

/// The free-space check (`tracking::free_space`): the depth image sees through a model
/// placed in front of the surfaces, not one placed on them. A frame whose registration explains what is left of the objects while
/// the depth image sees through the rest is not counted as good.
#[test]
fn a_pose_the_depth_image_sees_through_is_not_tracked() {
    let mesh = room(5);
    let cam = vga().halved();
    let first = render_frame(&mesh, cam, &Pose::identity());
    let probe = FreeSpaceProbe::new(&object_model(&[(&first, Pose::identity())]).map);
    let f = frame(&first, 0);
    let shifted = |dz: f64| {
        probe.measure(&f, &Pose::from_parts(Translation3::new(0.0, 0.0, dz), UnitQuaternion::identity()), 0.02)
    };
    let (truth, nearer) = (shifted(0.0), shifted(-0.1));
    println!("free space at the truth {truth:?}, 10 cm nearer the camera {nearer:?}");
    assert!(truth.supported > 100 && truth.fraction() < 0.02, "{truth:?}");
    assert!(nearer.fraction() > 0.9, "{nearer:?}");

    // The left half of the image now looks through to 6 m: the objects there are gone.
    let mut gone = render_frame(&mesh, cam, &Pose::identity());
    let (width, far) = (cam.width as usize, (6.0 / cam.depth_scale_m) as u16);
    for row in gone.depth.chunks_mut(width) {
        row[..width / 2].fill(far);
    }
    let run = |max_free_space: f64| {
        let params = TrackerParams { max_free_space, ..TrackerParams::default() };
        let model = object_model(&[(&first, Pose::identity())]);
        let mut tracker = Tracker::new(params, cam.width as usize, cam.height as usize, vec![model]).expect("tracker");
        assert!(step(&mut tracker, &first, 0).is_fresh());
        step(&mut tracker, &gone, 1)
    };
    let (checked, unchecked) = (run(TrackerParams::default().max_free_space), run(1.0));
    println!("with the check: {checked:?}\nwithout: {unchecked:?}");
    // What is left fits the model well, so the quality alone accepts the frame.
    assert!(unchecked.is_fresh() && unchecked.quality >= TrackerParams::default().min_quality, "{unchecked:?}");
    assert!(checked.free_space > 0.2, "{checked:?}");
    assert_eq!((checked.quality, checked.free_space), (unchecked.quality, unchecked.free_space));
    assert!(checked.is_held(), "the frame's registration counts as failed: {checked:?}");
}

/// A camera that jumps 9 cm sideways and back (the motion reverses): the
/// constant-velocity prediction is 18 cm off and its registration fails; the retry from
/// the last pose (9 cm off) tracks the frame.
#[test]
fn a_failed_prediction_is_retried_from_the_last_pose() {
    let mesh = room(5);
    let cam = vga().halved();
    let first = render_frame(&mesh, cam, &Pose::identity());
    let jumped = render_frame(&mesh, cam, &left_increment(&Vector6::new(0.09, 0.0, 0.0, 0.0, 0.0, 0.0)));
    let run = |retry_from_last_pose: bool| {
        // The paper's 10 points per surfel at this QVGA size: with 5
        // (`scene_min_points_by_image_size`, for small objects) this room lands 2.35 mm
        // off instead of 0.55 mm (docs/evaluation.md, "Small objects at QVGA").
        let params =
            TrackerParams { retry_from_last_pose, scene_min_points_by_image_size: false, ..TrackerParams::default() };
        let model = object_model(&[(&first, Pose::identity())]);
        let mut tracker = Tracker::new(params, cam.width as usize, cam.height as usize, vec![model]).expect("tracker");
        let out = [step(&mut tracker, &first, 0), step(&mut tracker, &jumped, 1), step(&mut tracker, &first, 2)];
        for (k, e) in out.iter().enumerate() {
            println!(
                "retry {retry_from_last_pose}, frame {k}: {:?}, fresh {}, quality {:.2}",
                e.status,
                e.is_fresh(),
                e.quality
            );
        }
        out
    };
    let (without, with) = (run(false), run(true));
    assert!(without[..2].iter().chain(&with[..2]).all(PoseEstimate::is_fresh), "the jump itself is tracked");
    assert!(without[2].is_held(), "the prediction fails: {:?}", without[2]);
    assert!(with[2].is_fresh(), "the retry tracks the frame: {:?}", with[2]);
    let (mm, deg) = pose_error(&with[2].camera_from_object.inverse(), &Pose::identity());
    println!("retried frame: {:.2} mm {:.3}°", mm * 1e3, deg);
    assert!(mm < 2e-3 && deg < 0.25, "{:.2} mm {:.3}°", mm * 1e3, deg);
}

/// After a loss the object is looked for around its last pose first: a camera that
/// turns away and comes back to where tracking was lost is tracked again at once, far
/// from the configured initial pose.
#[test]
fn a_lost_object_is_looked_for_where_it_was_last_seen() {
    let mesh = room(5);
    let cam = vga().halved();
    let poses: Vec<Pose> =
        (0..10).map(|k| left_increment(&(Vector6::new(0.008, -0.003, 0.006, 0.002, 0.004, 0.0) * k as f64))).collect();
    let frames: Vec<RenderTarget> = poses.iter().map(|p| render_frame(&mesh, cam, p)).collect();
    let away = render_frame(&mesh, cam, &left_increment(&Vector6::new(0.0, 0.0, 0.0, 0.0, 2.4, 0.0)));
    let views = [(&frames[0], poses[0]), (&frames[9], poses[9])];
    let run = |search_near_last_pose: bool| {
        let params = TrackerParams { search_near_last_pose, ..TrackerParams::default() };
        let mut tracker =
            Tracker::new(params, cam.width as usize, cam.height as usize, vec![object_model(&views)]).expect("tracker");
        for (k, t) in frames.iter().enumerate() {
            assert!(step(&mut tracker, t, k as u64).is_fresh(), "frame {k}");
        }
        let lost: Vec<TrackingStatus> = (20..23).map(|k| step(&mut tracker, &away, k).status).collect();
        assert_eq!(lost.last(), Some(&TrackingStatus::Lost));
        // Back where it was lost: frames until tracked again (none within 20: 20).
        let back = &frames[9];
        let frames_to_track = (30..50).position(|k| step(&mut tracker, back, k).is_fresh()).unwrap_or(20);
        (frames_to_track, tracker)
    };
    let ((near, mut tracker), (configured, _)) = (run(true), run(false));
    println!(
        "frames until tracked again: {near} (near the last pose first), {configured} (configured hypotheses only)"
    );
    assert_eq!(near, 0, "the first hypothesis is the last pose");
    assert!(configured > near);
    let e = step(&mut tracker, &frames[9], 60);
    let (mm, _) = pose_error(&e.camera_from_object.inverse(), &poses[9]);
    assert!(e.is_fresh() && mm < 2e-3, "{:.2} mm", mm * 1e3);
}

/// Objects that stay put relative to each other (`TrackerParams::follow_tracked_objects`):
/// the right group is hidden (its pixels without depth) for six frames while the camera
/// moves on and the left group stays tracked. Lost, the right group is looked for where
/// the left group's motion carried it (every other frame; the others try its configured
/// pose: no search region), 9-15 mm from the truth, and is tracked again as soon as it is
/// back; without that, it is looked for where it was last seen in the camera's frame,
/// 5-10 cm away by then, and is not found.
#[test]
fn a_lost_object_follows_the_camera_motion_the_others_measure() {
    let scene = TwoGroupsRun::new();
    let (cam, poses, frames) = (scene.cam, &scene.poses, &scene.targets);
    let (left, right) = scene.models(SearchRegion { translation_m: 0.0, yaw_rad: 0.0 });
    let hidden = TwoGroupsRun::HIDDEN;
    let run = |follow_tracked_objects: bool| {
        let params = TrackerParams { follow_tracked_objects, ..TrackerParams::default() };
        let models = vec![left.clone(), right.clone()];
        let mut tracker = Tracker::new(params, cam.width as usize, cam.height as usize, models).expect("tracker");
        let mut out = [blank(), blank()];
        let mut right_seen = Vec::new();
        for k in 0..frames.len() {
            tracker.step(&scene.frame(k, k as u64 * 33_000_000), &mut out);
            assert!(out[0].is_fresh(), "frame {k}: the left group stays tracked");
            right_seen.push(out[1]);
        }
        right_seen
    };
    let (followed, stayed) = (run(true), run(false));
    for (name, seen) in [("followed", &followed), ("stayed", &stayed)] {
        let line: Vec<String> = seen
            .iter()
            .zip(poses)
            .map(|(e, p)| {
                let (mm, deg) = pose_error(&e.camera_from_object, &(p.inverse() * right.initial_camera_from_object));
                format!("{:?}{} {:.1}mm {deg:.2}deg", e.status, u8::from(e.is_fresh()), mm * 1e3)
            })
            .collect();
        println!("{name}: {line:?}");
        assert!(seen[..4].iter().all(PoseEstimate::is_fresh), "{name}: the right group is tracked before it is hidden");
        assert_eq!(seen[6].status, TrackingStatus::Lost, "{name}: lost at the third frame without it");
    }
    let back = hidden.end;
    let found = (back..frames.len()).find(|&k| followed[k].is_fresh()).expect("found again");
    assert!(found <= back + 1, "found again within two frames of its return (frame {found})");
    for k in found..frames.len() {
        let (mm, deg) =
            pose_error(&followed[k].camera_from_object, &(poses[k].inverse() * right.initial_camera_from_object));
        // As tracked before it was hidden (0.6-1.3 mm, 0.3-1.2 deg).
        assert!(followed[k].is_fresh() && mm < 10e-3 && deg < 2.0, "frame {k}: {:.2} mm, {deg:.2} deg", mm * 1e3);
    }
    assert!(stayed[back..].iter().all(|e| !e.is_fresh()), "not where it was last seen in the camera's frame");
}
