//! Interrupting the offline commands (Ctrl-C, SIGTERM, or a `Stop` requested by the
//! caller): the frame loop stops before its next frame, the outputs are complete files
//! that hold the frames before it and say so, an existing model is never replaced by an
//! interrupted one, and the process exits with status 130.

mod common;

use common::*;
use mrsmap::app::interrupt::{Interrupted, Stop};
use mrsmap::io::recording::RecordingTopics;
use mrsmap::io::tracker_config::read_tracker_config;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Command, Stdio};

/// The pose lines of a TUM trajectory file and its comment lines.
fn trajectory(path: &Path) -> (usize, String) {
    let text = std::fs::read_to_string(path).expect("trajectory written");
    let poses = text.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty()).count();
    let comments = text.lines().filter(|l| l.starts_with('#')).collect::<Vec<_>>().join("\n");
    (poses, comments)
}

#[test]
fn odometry_stopped_after_three_frames_writes_their_trajectory() {
    let dir = temp_dir("interrupt-odometry");
    let out = dir.join("traj.txt");
    let job = mrsmap::app::odometry::OdometryJob {
        stop: Stop::after_frames(3),
        ..odometry_job(teddy_clip(), out.clone(), 2)
    };
    let s = mrsmap::app::odometry::run(&job).expect("an interrupted run is not an error");
    assert_eq!(s.interrupted, Some(Interrupted { after: 3, of: Some(8) }));
    assert_eq!((s.frames, s.registered), (3, 2));
    let (poses, comments) = trajectory(&out);
    assert_eq!(poses, 3);
    assert!(comments.contains("# interrupted after 3 of 8 frames"), "{comments}");
    // Stopped before the first frame: an empty trajectory that says why.
    let job = mrsmap::app::odometry::OdometryJob { stop: Stop::after_frames(0), ..job };
    let s = mrsmap::app::odometry::run(&job).expect("runs");
    assert_eq!((s.frames, s.interrupted.map(|i| i.after)), (0, Some(0)));
    assert_eq!(trajectory(&out).0, 0);
}

#[test]
fn map_stopped_early_fuses_its_key_views_but_never_replaces_an_existing_model() {
    let dir = temp_dir("interrupt-map");
    let out = dir.join("teddy.mrsm");
    std::fs::write(&out, b"the model the user already has").expect("write");
    let job = mrsmap::app::mapper::MapJob {
        dataset: teddy_clip(),
        camera: fr3_camera_file(),
        object: Some(root().join("robot_config/objects/teddy.toml")),
        out: Some(out.clone()),
        force: true,
        trajectory: Some(dir.join("slam.txt")),
        threads: Some(2),
        max_frames: None,
        params: Default::default(),
        stop: Stop::after_frames(4),
    };
    let s = mrsmap::app::mapper::run(&job).expect("an interrupted run is not an error");
    assert_eq!(s.interrupted, Some(Interrupted { after: 4, of: Some(8) }));
    assert_eq!(std::fs::read(&out).expect("kept"), b"the model the user already has");
    let written = dir.join("teddy.interrupted.mrsm");
    assert_eq!(s.model_path.as_deref(), Some(written.as_path()));
    let model = mrsmap::model::load(&written).expect("the interrupted model is a complete file");
    assert_eq!(model.header.source.frames, 4);
    let (poses, comments) = trajectory(&dir.join("slam.txt"));
    assert_eq!(poses, 4);
    assert!(comments.contains("# interrupted after 4 of 8 frames"), "{comments}");
    // Without an existing model, the interrupted one goes where it was asked to.
    std::fs::remove_file(&out).expect("remove");
    let s =
        mrsmap::app::mapper::run(&mrsmap::app::mapper::MapJob { stop: Stop::after_frames(4), ..job }).expect("runs");
    assert_eq!(s.model_path.as_deref(), Some(out.as_path()));
    assert_eq!(mrsmap::model::load(&out).expect("model").header.source.frames, 4);
}

#[test]
fn convert_and_replay_stopped_early_finish_their_mcap_files() {
    let dir = temp_dir("interrupt-mcap");
    let recording = dir.join("teddy.mcap");
    let convert = mrsmap::app::convert::ConvertJob {
        dataset: teddy_clip(),
        camera: None,
        out: recording.clone(),
        force: false,
        depth_encoding: mrsmap::io::mcap_write::DepthEncoding::Mm16,
        compression: mcap::Compression::Zstd,
        chunk_bytes: mrsmap::io::mcap_write::DEFAULT_CHUNK_BYTES,
        topics: RecordingTopics::default(),
        first_frame: 0,
        max_frames: None,
        stop: Stop::after_frames(5),
    };
    let s = mrsmap::app::convert::run(&convert).expect("an interrupted conversion is not an error");
    assert_eq!((s.written, s.interrupted), (5, Some(Interrupted { after: 5, of: Some(8) })));
    assert!(!dir.join("teddy.mcap.partial").exists());

    let config = read_tracker_config(&write_tracker_config(&dir, "interrupt", "")).expect("config");
    let poses = dir.join("poses.mcap");
    let replay = mrsmap::app::replay::ReplayJob {
        input: recording,
        out: Some(poses.clone()),
        force: false,
        trajectory: Some(dir.join("replay.txt")),
        topics: RecordingTopics::default(),
        camera: None,
        groundtruth: None,
        every: 1,
        qvga: false,
        max_frames: None,
        stop: Stop::after_frames(2),
    };
    // The converted file is complete: indexed reading sees its five frames.
    let s = mrsmap::app::replay::run(&config, &replay).expect("an interrupted replay is not an error");
    assert_eq!(s.interrupted, Some(Interrupted { after: 2, of: Some(5) }));
    assert_eq!(s.tracked_frames, 2);
    assert_eq!(s.mode, mrsmap::io::mcap_source::ReadMode::Indexed);
    let bytes = std::fs::read(&poses).expect("poses written");
    let summary = mcap::Summary::read(&bytes).expect("a finished MCAP file").expect("with a summary");
    let messages = summary.stats.expect("statistics").message_count;
    // A ROS 2 pose, a Foxglove one and a transform per tracked frame; the model once.
    assert_eq!(messages, 3 * s.objects[0].1[0] as u64 + 1, "the poses of the two frames tracked");
    let (lines, comments) = trajectory(&dir.join("replay.txt"));
    assert_eq!(lines, s.objects[0].1[0]);
    assert!(comments.contains("# interrupted after 2 of 5 frames"), "{comments}");
}

#[test]
fn track_dataset_stopped_early_writes_the_frames_tracked() {
    let dir = temp_dir("interrupt-track");
    let config = read_tracker_config(&write_tracker_config(&dir, "interrupt-track", "")).expect("config");
    let job = mrsmap::app::track_dataset::TrackDatasetJob {
        dataset: teddy_clip(),
        camera: fr3_camera_file(),
        first_frame: 0,
        every: 1,
        max_frames: None,
        qvga: true,
        start_at_ground_truth: false,
        detector: None,
        trajectory: Some(dir.join("track.txt")),
        overlay: None,
        stop: Stop::after_frames(3),
    };
    let s = mrsmap::app::track_dataset::run(&config, &job).expect("an interrupted run is not an error");
    assert_eq!(s.interrupted, Some(Interrupted { after: 3, of: Some(8) }));
    assert_eq!(s.objects[0].statuses.iter().sum::<usize>(), 3);
    let (poses, comments) = trajectory(&dir.join("track.txt"));
    assert_eq!(poses, s.objects[0].statuses[0]);
    assert!(comments.contains("# interrupted after 3 of 8 frames"), "{comments}");
}

#[test]
fn sigint_stops_the_odometry_process_with_status_130_and_a_complete_trajectory() {
    let dir = temp_dir("interrupt-process");
    let out = dir.join("traj.txt");
    let mut child = ChildGuard(
        Command::new(mrsmap_bin())
            .args(["odometry", "--dataset"])
            .arg(teddy_clip())
            .arg("--camera")
            .arg(fr3_camera_file())
            .arg("--out")
            .arg(&out)
            .args(["--threads", "1"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("mrsmap starts"),
    );
    let mut stderr = BufReader::new(child.0.stderr.take().expect("stderr"));
    let mut line = String::new();
    // The start line comes once the handlers are installed.
    while !line.contains("Ctrl-C stops") {
        line.clear();
        assert!(stderr.read_line(&mut line).expect("stderr") > 0, "the process ended before starting");
    }
    let sent = Command::new("kill").args(["-INT", &child.0.id().to_string()]).status().expect("kill runs");
    assert!(sent.success());
    let mut rest = String::new();
    stderr.read_to_string(&mut rest).expect("stderr");
    let status = child.0.wait().expect("exits");
    assert_eq!(status.code(), Some(130), "stderr: {rest}");
    // "interrupted after N of 8 frames": the trajectory holds those N frames.
    let after: usize = rest
        .split("interrupted after ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no report of the interruption in {rest:?}"));
    assert!(after < 8, "stopped before the end");
    let (poses, comments) = trajectory(&out);
    assert_eq!(poses, after);
    assert!(comments.contains(&format!("# interrupted after {after} of 8 frames")), "{comments}");
}
