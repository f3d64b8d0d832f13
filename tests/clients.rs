//! What clients and drivers see of the services: the pose client's JSON lines for
//! programs without iceoryx2, and a driver beyond a service's limit of publishers.

mod common;

use common::process::{finish, signal, start, wait_for};
use common::*;
use mrsmap::io::tracker_config::read_tracker_config;
use std::process::Command;

#[test]
fn the_pose_client_prints_json_lines_a_program_can_read() {
    let dir = temp_dir("poses-json");
    let config_path = write_tracker_config(&dir, "posesjson", "");
    let config = read_tracker_config(&config_path).expect("config");
    let (tracker, tracker_err) = start(&["track", "--config", path_str(&config_path)]);
    wait_for(&tracker_err, "ready", 60);
    let (client, client_err) =
        start(&["poses", "--service", &config.poses_service, "--json", "--count", "8", "--timeout", "30"]);
    wait_for(&client_err, "reading", 30);
    let (clip, camera_file) = (teddy_clip(), fr3_camera_file());
    let camera = ["camera", "--dataset", path_str(&clip), "--camera", path_str(&camera_file)];
    let (driver, _) = start(&[&camera[..], &["--service", &config.camera_service, "--rate", "10"]].concat());
    assert_eq!(finish(driver, 60).0, Some(0));
    let (code, out) = finish(client, 60);
    assert_eq!(code, Some(0), "{out}");
    // Only the poses on stdout (the summary went to stderr): one JSON object a line.
    let poses: Vec<serde_json::Value> =
        out.lines().map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}"))).collect();
    assert_eq!(poses.len(), 8, "{out}");
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
    signal(&tracker.0, "INT");
    assert_eq!(finish(tracker, 30).0, Some(0));
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
