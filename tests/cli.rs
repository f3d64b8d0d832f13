//! The `mrsmap` binary: help, exit codes, the odometry and eval commands end to end.

mod common;

use common::*;
use std::process::Command;

fn mrsmap(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_mrsmap")).args(args).output().expect("binary runs")
}

#[test]
fn help_teaches_the_commands() {
    let out = mrsmap(&["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for word in ["odometry", "eval", "bench"] {
        assert!(text.contains(word), "{text}");
    }
    let out = mrsmap(&["odometry", "--help"]);
    let text = String::from_utf8_lossy(&out.stdout);
    for word in ["--dataset", "--camera", "--qvga", "--timings", "depth"] {
        assert!(text.contains(word), "{text}");
    }
}

#[test]
fn odometry_then_eval_end_to_end() {
    let dir = temp_dir("cli");
    let (traj, timings) = (dir.join("traj.txt"), dir.join("timings.csv"));
    let clip = teddy_clip();
    let out = mrsmap(&[
        "odometry",
        "--dataset",
        clip.to_str().expect("utf-8"),
        "--camera",
        fr3_camera_file().to_str().expect("utf-8"),
        "--out",
        traj.to_str().expect("utf-8"),
        "--timings",
        timings.to_str().expect("utf-8"),
        "--threads",
        "2",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("8 frames, 7 registered") && text.contains("RPE"), "{text}");
    let csv = std::fs::read_to_string(&timings).expect("timings");
    assert_eq!(csv.lines().next(), Some("stamp,build_ms,register_ms,associations,iterations"));
    assert_eq!(csv.lines().count(), 9);
    let gt = clip.join("groundtruth.txt");
    for metric in ["rpe", "ate"] {
        let out = mrsmap(&["eval", metric, gt.to_str().expect("utf-8"), traj.to_str().expect("utf-8")]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("median") && text.contains("rmse"), "{text}");
    }
}

#[test]
fn errors_exit_non_zero_and_name_the_problem() {
    let out = mrsmap(&["odometry", "--dataset", "x"]);
    assert_eq!(out.status.code(), Some(2), "usage errors exit with 2");
    let out = mrsmap(&[
        "odometry",
        "--dataset",
        teddy_clip().to_str().expect("utf-8"),
        "--camera",
        "/no/such/camera.toml",
        "--out",
        "/tmp/x.txt",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/no/such/camera.toml"));
}
