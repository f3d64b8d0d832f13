//! The tracking, bench and quality commands end to end on the shipped clip.

mod common;

use common::*;
use mrsmap::app::track_dataset::TrackDatasetJob;
use mrsmap::io::tracker_config::read_tracker_config;
use mrsmap::io::tum::{TumDataset, format_stamp};
use std::process::Command;

#[test]
fn the_readme_demo_runs_two_processes_and_tracks_every_frame() {
    let out = Command::new(env!("CARGO_BIN_EXE_mrsmap"))
        .args(["demo", "--rate", &camera_hz(20)])
        .current_dir(root())
        .output()
        .expect("demo runs");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(text.contains("8 poses received, 8 tracking") && text.contains("error vs motion capture"), "{text}");
}

#[test]
fn the_demo_ends_promptly_and_explains_the_frames_a_slower_tracker_dropped() {
    // A frame every millisecond: faster than the tracker, as a slow robot computer is
    // against a 30 Hz camera. It drops the frames a newer one replaced; the demo must not
    // wait for them (it waited a minute before) and must say why they have no pose.
    let started = std::time::Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_mrsmap"))
        .args(["demo", "--rate", "1000"])
        .current_dir(root())
        .output()
        .expect("demo runs");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(started.elapsed() < std::time::Duration::from_secs(20), "the demo waited for dropped frames: {text}");
    let received: usize = text
        .split("demo: ")
        .nth(2)
        .and_then(|s| s.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("the demo counts the poses: {text}"));
    assert!(received <= 8, "{text}");
    let explained = format!("demo: {} of 8 frames got no pose.", 8 - received);
    assert_eq!(text.contains(&explained), received < 8, "{text}");
    if received < 8 {
        assert!(text.contains("` sends them slowly enough to see every frame"), "{text}");
        assert!(text.contains("dropped as stale), stopped by signal"), "the tracker stops cleanly: {text}");
    }
}

#[test]
fn the_demo_reports_a_failed_camera_driver_and_a_bad_rate() {
    // The driver cannot read its camera file: the demo stops with the driver's reason (it
    // used to wait a minute for poses and report none).
    let dir = temp_dir("demo_bad_camera");
    let camera = dir.join("camera.toml");
    std::fs::write(&camera, "fx = \"not a number\"\n").expect("write");
    let started = std::time::Instant::now();
    let out = mrsmap(&["demo", "--camera", path_str(&camera), "--rate", "30"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("the camera driver failed") && err.contains("camera.toml"), "{err}");
    assert!(started.elapsed() < std::time::Duration::from_secs(30), "{err}");
    for rate in ["-1", "nan", "inf"] {
        let out = mrsmap(&["demo", &format!("--rate={rate}")]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains("give frames per second"), "{err}");
    }
}

#[test]
fn bench_runs_on_the_shipped_clip_with_or_without_the_pose_graph() {
    let clip = teddy_clip();
    let camera = fr3_camera_file();
    for graph in ["0", "2"] {
        let args = [
            "bench",
            "--dataset",
            path_str(&clip),
            "--camera",
            path_str(&camera),
            "--passes",
            "1",
            "--resolution",
            "qvga",
        ];
        let out = mrsmap(&[&args[..], &["--graph-key-views", graph]].concat());
        assert!(out.status.success(), "--graph-key-views {graph}: {}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.starts_with("machine: "), "the figures say which machine ran them: {text}");
        assert!(text.contains("\ncompiled for: "), "the figures say what they were built for: {text}");
        assert!(text.contains("QVGA 320×240"), "{text}");
        assert_eq!(text.contains("pose-graph step"), graph != "0", "{text}");
    }
}

#[test]
fn bench_times_tracking_per_object_with_the_start_up_frame_apart() {
    // The shipped configuration's teddy, and the same model a second time under another
    // name: a row per object and one for the whole step.
    let dir = temp_dir("bench_two");
    let shipped = std::fs::read_to_string(root().join("robot_config/tracker.toml")).expect("the shipped config");
    let models = root().join("models/teddy.mrsm");
    let teddy = format!("\"{}\"", models.display());
    let config = shipped.replace("\"../models/teddy.mrsm\"", &teddy);
    let second = config.split("\n[[object]]\n").nth(1).expect("an object table").replace("\"teddy\"", "\"teddy2\"");
    let config_path = dir.join("two.toml");
    std::fs::write(&config_path, format!("{config}\n[[object]]\n{second}")).expect("config written");
    let (clip, camera) = (teddy_clip(), fr3_camera_file());
    let args = ["bench", "--dataset", path_str(&clip), "--camera", path_str(&camera), "--passes", "1"];
    let more = ["--resolution", "qvga", "--graph-key-views", "0", "--tracking-first-frame", "0"];
    // A picture that would replace an input is refused before any run.
    let tracking = ["--tracking-config", path_str(&config_path)];
    let out = mrsmap(&[&args[..], &more[..], &tracking[..], &["--plot", path_str(&config_path)]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("is the tracker configuration, which this run reads"), "{err}");
    assert!(out.stdout.is_empty(), "nothing ran: {}", String::from_utf8_lossy(&out.stdout));
    let plot = dir.join("times.svg");
    let out = mrsmap(&[&args[..], &more[..], &tracking[..], &["--plot", path_str(&plot)]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let svg = std::fs::read_to_string(&plot).expect("the picture");
    for panel in ["odometry QVGA 320×240", "tracking QVGA 320×240, teddy:", "tracking QVGA 320×240, teddy2:"] {
        assert!(svg.contains(panel), "a panel for {panel}: {svg}");
    }
    assert!(!svg.contains("#999"), "one pass: no line between passes");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("| object | threads | frames (estimated) | per frame median / p99 (ms) | scene map / registration median (ms) | first frame (ms) |"),
        "{text}"
    );
    let ms = |cell: &str| -> Vec<f64> { cell.split(" / ").map(|v| v.parse().expect("a number")).collect() };
    let row = |name: &str| -> Vec<String> {
        let line = text.lines().find(|l| l.starts_with(&format!("| QVGA 320×240 | {name} |")));
        line.unwrap_or_else(|| panic!("no tracking row for {name}: {text}"))
            .split('|')
            .map(|c| c.trim().to_string())
            .collect()
    };
    for name in ["teddy", "teddy2"] {
        let cells = row(name);
        // Eight frames: the first after start-up apart, seven in the median and p99,
        // every one estimated (the clip's teddy is tracked throughout).
        assert_eq!(cells[4], "7 (7)", "{text}");
        assert!(ms(&cells[5]).iter().chain(&ms(&cells[6])).all(|&t| t > 0.0), "{text}");
        assert!(cells[7].parse::<f64>().is_ok_and(|ms| ms > 0.0), "{text}");
    }
    let step = row("all 2, the whole step");
    assert_eq!(step[4], "7", "{text}");
    let (step_ms, teddy_ms) = (ms(&step[5])[0], ms(&row("teddy")[5])[0]);
    assert!(step_ms >= teddy_ms, "the whole step ({step_ms} ms) holds each object's ({teddy_ms} ms): {text}");
    // Two passes: one line between them in each of the three panels.
    let plot2 = dir.join("times_two_passes.svg");
    let two = ["bench", "--dataset", path_str(&clip), "--camera", path_str(&camera), "--passes", "2"];
    let out2 = mrsmap(&[&two[..], &more[..], &tracking[..], &["--plot", path_str(&plot2)]].concat());
    assert!(out2.status.success(), "{}", String::from_utf8_lossy(&out2.stderr));
    let svg2 = std::fs::read_to_string(&plot2).expect("the picture");
    assert_eq!(svg2.matches("stroke=\"#999\"").count(), 3, "{svg2}");
}

#[test]
fn offline_tracking_every_nth_frame() {
    let dir = temp_dir("every");
    let traj = dir.join("traj.txt");
    let (clip, camera, config) = (teddy_clip(), fr3_camera_file(), root().join("robot_config/tracker.toml"));
    let args = ["track", "--config", path_str(&config), "--dataset", path_str(&clip), "--camera", path_str(&camera)];
    let out = mrsmap(&[&args[..], &["--every", "3", "--qvga", "--trajectory", path_str(&traj)]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("3 frames tracking"), "frames 0, 3 and 6 of 8: {text}");
    // The published covariances against the ground truth: per frame, and per change
    // between consecutive tracked frames (here 3 frames apart).
    for what in ["(3 frames, unaligned)", "(2 changes of the error between consecutive frames)"] {
        assert!(text.contains(&format!("covariance (clustered) vs ground truth {what}: the errors are")), "{text}");
    }
    let stamps: Vec<String> = std::fs::read_to_string(&traj)
        .expect("trajectory")
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split(' ').next().unwrap_or_default().to_string())
        .collect();
    let frames = TumDataset::open(&clip).expect("clip").frames;
    let depth: Vec<String> = [0, 3, 6].iter().map(|&i| format_stamp(frames[i].depth_stamp_ns)).collect();
    assert_eq!(stamps, depth, "depth stamps of the tracked frames");
    let out = mrsmap(&[&args[..], &["--every", "0"]].concat());
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--every"), "names the option");
    // The library job refuses it too (as replay's), rather than reading it as 1.
    let config = read_tracker_config(&config).expect("config");
    let job = TrackDatasetJob {
        dataset: clip,
        camera,
        first_frame: 0,
        every: 0,
        max_frames: None,
        qvga: true,
        start_at_ground_truth: false,
        detector: None,
        trajectory: None,
        overlay: None,
        stop: Default::default(),
    };
    let err = mrsmap::app::track_dataset::run(&config, &job).expect_err("every 0 is refused");
    assert!(err.to_string().contains("--every"), "{err}");
}

#[test]
fn outputs_that_fail_at_the_end_of_a_run_are_rescued_not_lost() {
    // A full disk at the end of a run, made reproducible: the temporary file each output
    // is written through is a link to /dev/full, where every write fails with ENOSPC.
    let dir = temp_dir("cli-rescue");
    let (clip, camera) = (teddy_clip(), fr3_camera_file());
    let (traj, timings) = (dir.join("odo.txt"), dir.join("timings.csv"));
    for p in [&traj, &timings] {
        let partial = std::path::PathBuf::from(format!("{}.partial", p.display()));
        let _ = std::fs::remove_file(&partial);
        std::os::unix::fs::symlink("/dev/full", &partial).expect("symlink");
    }
    let args = ["odometry", "--dataset", path_str(&clip), "--camera", path_str(&camera), "--out", path_str(&traj)];
    let out = mrsmap(&[&args[..], &["--timings", path_str(&timings)]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    // Both outputs are tried and both rescued; the cause is said once.
    let rescued = |name: &str| std::env::temp_dir().join(format!("mrsmap-rescued-{}-{name}", out_pid(&err, name)));
    let (rescued_traj, rescued_timings) = (rescued("odo.txt"), rescued("timings.csv"));
    assert!(err.contains(&format!("written to {} instead", rescued_traj.display())), "{err}");
    assert!(err.contains(&format!("\nand could not write {}", timings.display())), "{err}");
    assert_eq!(err.matches("No space left on device").count(), 1, "{err}");
    // The rescued trajectory is the one a good disk gets, and nothing is left behind.
    let good = dir.join("good.txt");
    assert!(
        mrsmap(&["odometry", "--dataset", path_str(&clip), "--camera", path_str(&camera), "--out", path_str(&good)])
            .status
            .success()
    );
    assert_eq!(std::fs::read(&rescued_traj).expect("rescued"), std::fs::read(&good).expect("good"));
    assert!(std::fs::read_to_string(&rescued_timings).expect("rescued").starts_with("stamp,build_ms"));
    assert!(!traj.exists() && !timings.exists());
    for p in [rescued_traj, rescued_timings] {
        let _ = std::fs::remove_file(p);
    }
}

/// The process id in a rescued file's name as the error gives it.
fn out_pid(err: &str, name: &str) -> String {
    let tail = format!("-{name} instead");
    let end = err.find(&tail).expect("a rescued file");
    let start = err[..end].rfind("mrsmap-rescued-").expect("its prefix") + "mrsmap-rescued-".len();
    err[start..end].to_string()
}

/// `eval tracking-quality --trials-csv` writes every registration, one row each, for a
/// rule of one's own.
#[test]
fn the_quality_measurement_writes_every_registration() {
    let dir = temp_dir("cli-trials-csv");
    let config = root().join("robot_config/tracker.toml");
    let clip = root().join("tests/data/fr3_teddy_8");
    let camera = root().join("robot_config/cameras/tum_fr3.toml");
    let quality = [
        "eval",
        "tracking-quality",
        "--config",
        path_str(&config),
        "--dataset",
        path_str(&clip),
        "--camera",
        path_str(&camera),
    ];
    // A file that cannot be written is refused before the run.
    let lost = ["--trials-csv", "/no/such/folder/trials.csv"];
    let out = mrsmap(&quality.iter().copied().chain(lost).collect::<Vec<_>>());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.code() == Some(1) && err.starts_with("error: --trials-csv ") && err.contains("cannot write"),
        "{err}"
    );
    let trials = dir.join("trials.csv");
    let extra = ["--first-frame", "0", "--frames", "8", "--trials", "2", "--trials-csv", path_str(&trials)];
    let args: Vec<&str> = quality.iter().copied().chain(extra).collect();
    let out = mrsmap(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let csv = std::fs::read_to_string(&trials).expect("the trials are written");
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows[0], "frame,stamp,quality,free_space,associations,error_mm,error_deg,failed");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let tracked: usize = stdout
        .split("reference: the ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("the reference's frames are printed");
    assert!(tracked >= 3, "{stdout}");
    assert_eq!(rows.len() - 1, 2 * tracked, "two registrations per tracked frame: {csv}");
    assert!(rows[1..].iter().all(|r| r.split(',').count() == 8), "{csv}");
}

#[test]
fn a_configuration_from_print_default_config_tracks_the_clip() {
    let out = mrsmap(&["track", "--print-default-config"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).expect("UTF-8");
    assert!(text.contains("[tracker]\n") && text.contains("[[object]]\n"), "{text}");
    // Where a user puts it: beside a models folder holding the model it names.
    let dir = temp_dir("default-config");
    std::fs::create_dir_all(dir.join("robot_config")).expect("folder");
    std::fs::create_dir_all(dir.join("models")).expect("folder");
    std::fs::copy(root().join("models/teddy.mrsm"), dir.join("models/teddy.mrsm")).expect("model");
    let config = dir.join("robot_config/mine.toml");
    std::fs::write(&config, &text).expect("config");
    let (clip, camera) = (teddy_clip(), fr3_camera_file());
    let args = ["track", "--config", path_str(&config), "--dataset", path_str(&clip), "--camera", path_str(&camera)];
    let out = mrsmap(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary = String::from_utf8_lossy(&out.stdout);
    assert!(summary.contains("8 frames tracking"), "{summary}");
    // Neither a configuration nor the request for one: the error says what to give.
    let out = mrsmap(&["track"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--config"), "{err}");
    let out = mrsmap(&["track", "--print-default-config", "--config", path_str(&config)]);
    assert!(!out.status.success(), "the request takes no other option");
}

#[test]
fn track_check_loads_everything_and_names_a_start_pose_out_of_view() {
    let config = root().join("robot_config/tracker.toml");
    let out = mrsmap(&["track", "--config", path_str(&config), "--check"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}{}", String::from_utf8_lossy(&out.stderr));
    assert!(text.contains("tracker.toml: valid") && text.contains("object 'teddy': model"), "{text}");
    assert!(text.contains("0.98 m away") && text.contains("would start"), "{text}");
    let dir = temp_dir("check");
    let shipped = std::fs::read_to_string(&config).expect("config");
    let models = root().join("models");
    let absolute = shipped.replace("\"../models/", &format!("\"{}/", models.display()));
    // The pose written the other way round (object_from_camera): it parses, and the
    // check says what it probably is.
    let start = shipped.lines().find(|l| l.starts_with("camera_from_object")).expect("a start pose");
    let inverted = "camera_from_object = [0.63604, 0.66766, 0.53327, 0.25098, 0.79599, -0.53327, -0.13797]";
    let path = dir.join("inverted.toml");
    std::fs::write(&path, absolute.replace(start, inverted)).expect("config");
    let out = mrsmap(&["track", "--config", path_str(&path), "--check"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(err.contains("warning: object 'teddy'") && err.contains("given as object_from_camera"), "{err}");
    // The live tracker says so too at start-up (and runs).
    let tag = format!("mrsmap_check_{}", std::process::id());
    let services: Vec<String> = ["cam", "poses", "det"].iter().map(|s| format!("{tag}/{s}")).collect();
    let out = mrsmap(&[
        "track",
        "--config",
        path_str(&path),
        "--idle-timeout",
        "0.2",
        "--camera-service",
        &services[0],
        "--poses-service",
        &services[1],
        "--detections-service",
        &services[2],
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("tracker: warning: object 'teddy'") && err.contains("tracker: ready"), "{err}");
    // An object registered with the colour term says so.
    let path = dir.join("colour.toml");
    std::fs::write(&path, absolute.replace("color_term = false", "color_term = true")).expect("config");
    let out = mrsmap(&["track", "--config", path_str(&path), "--check"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("registered with the colour term (luminance std inf, chroma std 0.03)"), "{text}");
    // A model that is not there: the tracker would not start.
    let path = dir.join("missing.toml");
    std::fs::write(&path, absolute.replace("teddy.mrsm", "no_such.mrsm")).expect("config");
    let out = mrsmap(&["track", "--config", path_str(&path), "--check"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("no_such.mrsm") && err.contains("'teddy'"), "{err}");
}
