//! What clients and drivers see of the services: the pose client's JSON lines for
//! programs without iceoryx2, a driver playing a clip back and forth, and a driver
//! beyond a service's limit of publishers.

mod common;

use common::process::{finish, signal, start, wait_for};
use common::*;
use mrsmap::io::tracker_config::read_tracker_config;
use mrsmap::io::tum::TumDataset;
use std::process::Command;

/// Runs a tracker, a pose client printing `count` poses as JSON lines, and a driver
/// publishing the shipped clip at 10 Hz ([`camera_hz`]) with `driver_args`; checks that
/// each process ends cleanly and returns the poses, one JSON object per stdout line.
fn json_poses_of_the_clip(tag: &str, count: usize, driver_args: &[&str]) -> Vec<serde_json::Value> {
    let dir = temp_dir(tag);
    let config_path = write_tracker_config(&dir, tag, "");
    let config = read_tracker_config(&config_path).expect("config");
    let (tracker, tracker_err) = start(&["track", "--config", path_str(&config_path)]);
    wait_for(&tracker_err, "ready", 60);
    let count = count.to_string();
    let (client, client_err) =
        start(&["poses", "--service", &config.poses_service, "--json", "--count", &count, "--timeout", "30"]);
    wait_for(&client_err, "reading", 30);
    let (clip, camera_file) = (teddy_clip(), fr3_camera_file());
    let camera = ["camera", "--dataset", path_str(&clip), "--camera", path_str(&camera_file)];
    let rate = camera_hz(10);
    let service = ["--service", &config.camera_service, "--rate", &rate];
    let (driver, _) = start(&[&camera[..], &service, driver_args].concat());
    assert_eq!(finish(driver, 60).0, Some(0));
    let (code, out) = finish(client, 60);
    assert_eq!(code, Some(0), "{out}");
    signal(&tracker.0, "INT");
    assert_eq!(finish(tracker, 30).0, Some(0));
    // Only the poses on stdout (the summary went to stderr): one JSON object a line.
    out.lines().map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}"))).collect()
}

#[test]
fn the_pose_client_prints_json_lines_a_program_can_read() {
    let poses = json_poses_of_the_clip("posesjson", 8, &[]);
    assert_eq!(poses.len(), 8, "{poses:?}");
    let sequences: Vec<u64> = poses.iter().map(|p| p["frame_sequence"].as_u64().expect("sequence")).collect();
    assert!(sequences.windows(2).all(|w| w[0] < w[1]), "{sequences:?}");
    for p in &poses {
        assert_eq!(p["object"], "teddy");
        assert_eq!(p["status"], "tracking", "{p}");
        assert_eq!(p["covariance"].as_array().map(Vec::len), Some(36));
        let z = p["camera_from_object"]["translation_m"][2].as_f64().expect("z");
        assert!((0.9..1.2).contains(&z), "the teddy is about a metre in front of the camera: {p}");
        assert!(p["latency_ms"].as_f64().is_some_and(|l| l >= 0.0));
    }
}

#[test]
fn a_bouncing_driver_plays_the_clip_back_and_forth_and_the_teddy_stays_tracked() {
    let poses = json_poses_of_the_clip("bounce", 12, &["--bounce", "--max-frames", "12"]);
    // The clip's 8 frames forwards, then back from the seventh: no frame twice in a row.
    let stamps: Vec<u64> =
        TumDataset::open(&teddy_clip()).expect("clip").frames.iter().map(|f| f.depth_stamp_ns).collect();
    let expected: Vec<u64> = [0, 1, 2, 3, 4, 5, 6, 7, 6, 5, 4, 3].iter().map(|&i| stamps[i]).collect();
    let sent: Vec<u64> = poses.iter().map(|p| p["frame_stamp_ns"].as_u64().expect("stamp")).collect();
    assert_eq!(sent, expected, "{poses:?}");
    assert!(poses.iter().all(|p| p["status"] == "tracking"), "{poses:?}");
}

#[test]
fn bouncing_is_refused_with_a_loop_or_a_recording() {
    for extra in [&["--dataset", "d", "--camera", "c", "--loop"][..], &["--mcap", "r.mcap"]] {
        let out = mrsmap(&[&["camera", "--bounce"][..], extra].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("'--bounce' cannot be used with"), "{err}");
    }
}

#[test]
fn a_driver_that_can_read_no_frame_says_so_and_fails() {
    // Longer datasets are read frame by frame: unreadable frames are skipped, but when
    // none can be read the driver stops (bouncing, it would try them again for ever).
    let dir = temp_dir("unreadable-driver");
    let listing: String = (0..65).map(|i| format!("{}.{i:02} rgb/{i}.png\n", 1000 + i / 30)).collect();
    std::fs::write(dir.join("rgb.txt"), &listing).expect("write");
    std::fs::write(dir.join("depth.txt"), listing.replace("rgb/", "depth/")).expect("write");
    let service = format!("mrsmap_unreadable_{}/camera", std::process::id());
    let camera_file = fr3_camera_file();
    let args = ["camera", "--dataset", path_str(&dir), "--camera", path_str(&camera_file), "--service", &service];
    let out = mrsmap(&[&args[..], &["--bounce", "--rate", "0"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("rgb/64.png") && err.contains("no frame could be read (65 tried"), "{err}");
}

#[test]
fn json_lines_and_quiet_are_refused_together() {
    let out = mrsmap(&["poses", "--json", "--quiet"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("'--json' cannot be used with '--quiet'"), "{err}");
}

#[test]
fn a_third_camera_driver_on_one_service_is_told_why_it_cannot_publish() {
    // A frame service takes two publishers (docs/wire-format.md): the third driver stops
    // with iceoryx2's reason and what to do about it.
    let service = format!("mrsmap_third_{}/camera", std::process::id());
    let (clip, camera_file) = (teddy_clip(), fr3_camera_file());
    let args = ["camera", "--dataset", path_str(&clip), "--camera", path_str(&camera_file), "--service", &service];
    let looping = [&args[..], &["--loop"]].concat();
    let (first, first_err) = start(&looping);
    wait_for(&first_err, "publishing", 30);
    let (second, second_err) = start(&looping);
    wait_for(&second_err, "publishing", 30);
    let out = Command::new(mrsmap_bin()).args(args).output().expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("ExceedsMaxSupportedPublishers") && err.contains("2 camera drivers on a frame service"),
        "{err}"
    );
    drop((first, second));
}
