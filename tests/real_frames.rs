//! Odometry on real TUM frames shipped in tests/data (CC BY 4.0, see SOURCE.txt there).

mod common;

use common::*;
use mrsmap::app::odometry::run;

#[test]
fn odometry_on_real_teddy_frames_is_accurate() {
    let dir = temp_dir("real-accuracy");
    let job = odometry_job(teddy_clip(), dir.join("traj.txt"), 2);
    let s = run(&job).expect("odometry runs");
    assert_eq!((s.frames, s.registered, s.failed, s.skipped), (8, 7, 0, 0));
    let rpe = s.rpe.expect("the clip has ground truth");
    println!("RPE median {:.3} mm max {:.3} mm", rpe.median * 1e3, rpe.max * 1e3);
    // Measured 2.5 / 4.1 mm; the original implementation's median on this sequence is 2.7.
    assert!(rpe.median < 3.5e-3 && rpe.max < 6.0e-3, "{rpe:?}");
}

#[test]
fn qvga_odometry_is_accurate() {
    let dir = temp_dir("real-qvga");
    let mut job = odometry_job(teddy_clip(), dir.join("traj.txt"), 2);
    job.qvga = true;
    let s = run(&job).expect("odometry runs");
    let rpe = s.rpe.expect("the clip has ground truth");
    println!("QVGA RPE median {:.3} mm max {:.3} mm", rpe.median * 1e3, rpe.max * 1e3);
    assert_eq!(s.failed, 0);
    assert!(rpe.median < 4.0e-3 && rpe.max < 8.0e-3, "{rpe:?}");
}

#[test]
fn testing_small_steps_first_changes_no_result() {
    // The tracker tests a small step's gain on the current associations before searching
    // every match afresh at it: the same test, so the same registrations, bit for bit. At
    // the tracker's 2 mm / 2 mrad tolerance, real frames give small steps that the gain
    // test rejects (on this clip, at VGA and QVGA).
    let dir = temp_dir("small-steps-first");
    let mut outputs = Vec::new();
    for (qvga, first) in [(false, false), (false, true), (true, false), (true, true)] {
        let out = dir.join(format!("traj_{qvga}_{first}.txt"));
        let mut job = odometry_job(teddy_clip(), out.clone(), 2);
        job.qvga = qvga;
        let r = &mut job.params.registration;
        (r.step_tolerance_m, r.step_tolerance_rad, r.test_small_steps_first) = (2e-3, 2e-3, first);
        run(&job).expect("odometry runs");
        outputs.push(std::fs::read(out).expect("trajectory written"));
    }
    assert!(outputs[0] == outputs[1], "VGA trajectories differ");
    assert!(outputs[2] == outputs[3], "QVGA trajectories differ");
}

#[test]
fn trajectory_is_bit_identical_for_any_thread_count() {
    let dir = temp_dir("determinism");
    let mut outputs = Vec::new();
    for threads in [1, 2, 3] {
        let out = dir.join(format!("traj{threads}.txt"));
        run(&odometry_job(teddy_clip(), out.clone(), threads)).expect("odometry runs");
        outputs.push(std::fs::read(out).expect("trajectory written"));
    }
    assert!(outputs[0] == outputs[1] && outputs[1] == outputs[2], "trajectories differ between thread counts");
}

#[test]
fn trajectory_is_in_tum_format_with_depth_stamps() {
    let dir = temp_dir("format");
    let out = dir.join("traj.txt");
    run(&odometry_job(teddy_clip(), out.clone(), 2)).expect("odometry runs");
    let text = std::fs::read_to_string(&out).expect("written");
    let assoc = std::fs::read_to_string(teddy_clip().join("associations.txt")).expect("clip");
    let depth_stamps: Vec<&str> = assoc.lines().map(|l| l.split_whitespace().nth(2).expect("4 fields")).collect();
    let lines: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(lines.len(), depth_stamps.len());
    for (line, stamp) in lines.iter().zip(&depth_stamps) {
        let f: Vec<&str> = line.split(' ').collect();
        assert_eq!(f.len(), 8, "{line}");
        assert_eq!(f[0], *stamp);
        let q: Vec<f64> = f[4..8].iter().map(|v| v.parse().expect("number")).collect();
        assert!((q.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-6, "unit quaternion");
    }
    // The first pose is the ground-truth pose of the first frame.
    let gt = mrsmap::io::tum::Trajectory::read(&teddy_clip().join("groundtruth.txt")).expect("gt");
    let est = mrsmap::io::tum::Trajectory::read(&out).expect("estimate");
    let first = gt.interpolate(est.stamps[0], 0.1).expect("inside the ground truth");
    let (t, deg) = pose_error(&first, &est.poses[0]);
    assert!(t < 1e-6 && deg < 1e-4);
}
