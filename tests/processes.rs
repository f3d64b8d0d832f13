//! The camera driver, the tracker and the pose client as separate processes: poses
//! against ground truth, faults (bad frames, a killed driver, missing or corrupt models),
//! clean shutdown on SIGTERM and SIGINT, and a detector that re-initialises a lost object.

mod common;

use common::process::{finish, signal, start, wait_for};
use common::*;
use mrsmap::eval::{ErrorStats, associate, ate_translation};
use mrsmap::io::camera_file::read_camera;
use mrsmap::io::frames::FrameLoader;
use mrsmap::io::ipc;
use mrsmap::io::tracker_config::read_tracker_config;
use mrsmap::io::tum::{Trajectory, TumDataset};
use mrsmap::io::wire::{FrameHeader, ObjectDetection, ObjectPose, RgbdFrameVga, detection_mode, status, write_frame};
use std::process::Command;
use std::time::Duration;

/// Starts `mrsmap camera` sending the shipped clip on `service`, with `extra` options.
fn start_clip_driver(service: &str, extra: &[&str]) -> ChildGuard {
    let (clip, camera_file) = (teddy_clip(), fr3_camera_file());
    let mut args =
        vec!["camera", "--dataset", path_str(&clip), "--camera", path_str(&camera_file), "--service", service];
    args.extend_from_slice(extra);
    start(&args).0
}

#[test]
fn driver_tracker_and_client_as_processes() {
    let dir = temp_dir("processes");
    let config_path = write_tracker_config(&dir, "e2e", "");
    let config = read_tracker_config(&config_path).expect("config");
    let traj = dir.join("poses.txt");
    let (tracker, tracker_err) = start(&["track", "--config", path_str(&config_path)]);
    // The start-up line says where the tracker listens and publishes.
    let ready = wait_for(&tracker_err, "ready", 60);
    let ports = format!("frames from {}/rgbd/vga, poses on {}", config.camera_service, config.poses_service);
    assert!(ready.last().is_some_and(|l| l.contains(&ports) && l.contains("'teddy'")), "{ready:?}");
    // And where its workers run: one CPU each when they are as many as the process's
    // CPUs (rayon's default count), else why not (`app::affinity`).
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let placement = mrsmap::app::affinity::plan(threads, mrsmap::app::affinity::allowed_cpus()).to_string();
    assert!(ready.last().is_some_and(|l| l.contains(&placement)), "{placement:?} in {ready:?}");
    let (client, client_err) = start(&[
        "poses",
        "--service",
        &config.poses_service,
        "--out",
        path_str(&traj),
        "--count",
        "8",
        "--timeout",
        "30",
    ]);
    wait_for(&client_err, "reading", 30);
    let camera = start_clip_driver(&config.camera_service, &["--rate", &camera_hz(10)]);
    assert_eq!(finish(camera, 60).0, Some(0), "the driver sends 8 frames and exits");
    let (code, out) = finish(client, 60);
    assert_eq!(code, Some(0), "client: {out}");
    assert!(out.contains("8 tracking"), "{out}");
    // The poses against the motion-capture ground truth (TUM ATE: object_from_camera
    // trajectory aligned rigidly to world_from_camera).
    let estimate = Trajectory::read(&traj).expect("client wrote the trajectory");
    let gt = Trajectory::read(&teddy_clip().join("groundtruth.txt")).expect("gt");
    let (r, e) = associate(&gt, &estimate, 0.02).expect("stamps match");
    let ate = ErrorStats::of(&ate_translation(&r, &e).expect("ate"));
    println!("ATE over {} poses: median {:.2} mm, max {:.2} mm", ate.count, ate.median * 1e3, ate.max * 1e3);
    assert_eq!(ate.count, 8);
    assert!(ate.max < 0.01, "max {:.2} mm", ate.max * 1e3);
    signal(&tracker.0, "TERM");
    let (code, out) = finish(tracker, 30);
    assert_eq!(code, Some(0), "clean shutdown on SIGTERM: {out}");
    assert!(out.contains("8 frames") && out.contains("stopped by signal"), "{out}");
}

/// Publishes frames from this test process, as a misbehaving driver would.
struct TestDriver {
    _node: iceoryx2::node::Node<ipc::Ipc>,
    publisher: iceoryx2::port::publisher::Publisher<ipc::Ipc, RgbdFrameVga, ()>,
    notifier: iceoryx2::port::notifier::Notifier<ipc::Ipc>,
    rgb: Vec<u8>,
    depth: Vec<u16>,
    header: FrameHeader,
}

impl TestDriver {
    fn new(camera_service: &str) -> Self {
        let node = ipc::node("test_driver").expect("node");
        let name = ipc::FrameSize::Vga.service(camera_service);
        let service = ipc::frames::<RgbdFrameVga>(&node, &name).expect("frames");
        let events = ipc::events(&node, &name).expect("events");
        let publisher = service.publisher_builder().create().expect("publisher");
        let notifier = events.notifier_builder().create().expect("notifier");
        let dataset = TumDataset::open(&teddy_clip()).expect("clip");
        let camera = read_camera(&fr3_camera_file()).expect("camera");
        let mut loader = FrameLoader::new(camera, false);
        let f = loader.load(&dataset.frames[0]).expect("frame");
        let header = FrameHeader::for_camera(&camera, f.stamp_ns, 0);
        TestDriver { _node: node, publisher, notifier, rgb: f.rgb.to_vec(), depth: f.depth.to_vec(), header }
    }

    /// The capture stamp of frame `sequence`: the clip's first, 33 ms later per frame.
    fn stamp_of(&self, sequence: u64) -> u64 {
        self.header.capture_stamp_ns + sequence * 33_333_333
    }

    /// Sends the clip's first frame with `sequence`, after `damage` changed it.
    fn send(&self, sequence: u64, damage: impl FnOnce(&mut RgbdFrameVga)) {
        let capture_stamp_ns = self.stamp_of(sequence);
        let header = FrameHeader { sequence, capture_stamp_ns, send_stamp_ns: ipc::now_ns(), ..self.header };
        let loan = self.publisher.loan_uninit().expect("loan");
        let mut sample = write_frame(loan, &header, &self.rgb, &self.depth).expect("fits");
        damage(sample.payload_mut());
        sample.send().expect("send");
        self.notifier.notify().expect("notify");
    }
}

fn read_pose(reader: &iceoryx2::port::reader::EntryHandle<ipc::Ipc, u32, ObjectPose>, sequence: u64) -> ObjectPose {
    for _ in 0..200 {
        let p = *reader.get();
        if p.frame_sequence == sequence && p.frame_send_stamp_ns != 0 {
            return p;
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    panic!("no pose for frame {sequence}");
}

#[test]
fn bad_frames_are_reported_invalid_and_a_killed_driver_is_survived() {
    let dir = temp_dir("faults");
    let config_path = write_tracker_config(&dir, "faults", "");
    let config = read_tracker_config(&config_path).expect("config");
    let (tracker, tracker_err) = start(&["track", "--config", path_str(&config_path)]);
    wait_for(&tracker_err, "ready", 60);
    // A client writing the poses, killed below: what it received is on disk.
    let kept = dir.join("kept.txt");
    let (client, client_err) =
        start(&["poses", "--service", &config.poses_service, "--out", path_str(&kept), "--quiet"]);
    wait_for(&client_err, "reading", 30);
    let driver = TestDriver::new(&config.camera_service);
    let node = ipc::node("test_reader").expect("node");
    let poses = ipc::open_poses(&node, &config.poses_service).expect("the tracker created the blackboard");
    let reader = poses.reader_builder().create().expect("reader");
    let entry = reader.entry::<ObjectPose>(&0).expect("object 0");
    let mut sequence = 0;
    let mut send = |damage: &dyn Fn(&mut RgbdFrameVga)| {
        sequence += 1;
        driver.send(sequence, damage);
        read_pose(&entry, sequence).status
    };
    assert_eq!(send(&|_| {}), status::TRACKING, "a good frame is tracked");
    assert_eq!(send(&|f| f.header.layout_version = 99), status::INVALID_FRAME, "another layout version");
    assert_eq!(send(&|f| f.header.fx = f64::NAN), status::INVALID_FRAME, "NaN intrinsics");
    assert_eq!(send(&|f| f.header.width = 320), status::INVALID_FRAME, "a header that disagrees with the message size");
    assert_eq!(send(&|f| f.depth.fill(0)), status::INVALID_FRAME, "all-zero depth");
    assert_eq!(send(&|_| {}), status::TRACKING, "tracking resumes");
    // A valid frame that does not show the object (a wall 1 m away): the registration
    // fails, the pose is held (still tracking, one bad frame), and the client's
    // trajectory says so instead of writing the held pose at this frame's stamp.
    sequence += 1;
    driver.send(sequence, |f| f.depth.fill(5000));
    let held = read_pose(&entry, sequence);
    assert_eq!((held.status, held.bad_frames, held.is_fresh()), (status::TRACKING, 1, false));
    sequence += 1;
    driver.send(sequence, |_| {});
    assert!(read_pose(&entry, sequence).is_fresh(), "tracking resumes");
    drop(driver);
    // A real driver, killed mid-stream and restarted: the tracker keeps going.
    let camera_args = ["--loop", "--rate", "20"];
    let camera = start_clip_driver(&config.camera_service, &camera_args);
    std::thread::sleep(Duration::from_millis(1500));
    signal(&camera.0, "KILL");
    drop(camera);
    let before = entry.get().publish_stamp_ns;
    std::thread::sleep(Duration::from_millis(500));
    let camera = start_clip_driver(&config.camera_service, &camera_args);
    std::thread::sleep(Duration::from_millis(1500));
    let after = *entry.get();
    assert!(after.publish_stamp_ns > before, "poses resume after the driver restarts");
    assert_eq!(after.status, status::TRACKING);
    drop(camera);
    signal(&client.0, "KILL");
    drop(client);
    let partial = dir.join("kept.txt.partial");
    let poses = Trajectory::read(&partial).expect("a killed client leaves a TUM trajectory");
    assert!(poses.poses.len() >= 10, "{} poses kept", poses.poses.len());
    let text = std::fs::read_to_string(&partial).expect("reads");
    let held_line = format!("# {} held", mrsmap::io::tum::format_stamp(held.frame_stamp_ns));
    assert!(text.contains(&held_line), "{held_line} in {text}");
    let again = Command::new(mrsmap_bin())
        .args(["poses", "--service", &config.poses_service, "--out", path_str(&kept), "--timeout", "1"])
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(!again.status.success() && err.contains("kept.txt.partial exists") && err.contains("--force"), "{err}");
    signal(&tracker.0, "INT");
    let (code, out) = finish(tracker, 30);
    assert_eq!(code, Some(0), "clean shutdown on SIGINT: {out}");
    assert!(out.contains("refused as invalid"), "{out}");
}

/// Runs `mrsmap ARGS` to its end while `send` feeds the tracker frames; returns whether
/// it succeeded, and its stdout.
fn run_while_sending(args: &[&str], send: &mut dyn FnMut()) -> (bool, String) {
    let (mut child, _) = start(args);
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    let exit = loop {
        if let Some(exit) = child.0.try_wait().expect("wait") {
            break exit;
        }
        assert!(std::time::Instant::now() < deadline, "mrsmap {args:?} did not exit");
        send();
        std::thread::sleep(Duration::from_millis(30));
    };
    let mut out = String::new();
    std::io::Read::read_to_string(&mut child.0.stdout.take().expect("stdout"), &mut out).expect("reads");
    (exit.success(), out)
}

#[test]
fn a_detection_finds_an_object_the_tracker_could_not() {
    // The configured pose is 0.4 m off and there is no search region: on its own the
    // tracker never finds the teddy. `mrsmap detect` with its true pose (in the clip's
    // first frame, which the driver below sends over and over) makes it track. The run
    // is recorded, and its replay applies the detection again before the same frame.
    let dir = temp_dir("detections");
    let text = tracker_config_text("detect", "")
        .replace("camera_from_object = [0.1923,", "camera_from_object = [0.5923,")
        .replace("search_translation_m = 0.05\nsearch_yaw_deg = 20.0", "");
    let config_path = dir.join("tracker.toml");
    std::fs::write(&config_path, text).expect("write config");
    let config = read_tracker_config(&config_path).expect("config");
    let recorded = dir.join("recorded.mcap");
    let (tracker, tracker_err) = start(&["track", "--config", path_str(&config_path), "--record", path_str(&recorded)]);
    wait_for(&tracker_err, "ready", 60);
    let driver = TestDriver::new(&config.camera_service);
    let node = ipc::node("test_detector").expect("node");
    let poses = ipc::open_poses(&node, &config.poses_service).expect("the tracker created the blackboard");
    let reader = poses.reader_builder().create().expect("reader");
    let entry = reader.entry::<ObjectPose>(&0).expect("object 0");
    let (mut sequence, mut fresh) = (0, 0);
    let mut send = || {
        sequence += 1;
        driver.send(sequence, |_| {});
        let pose = read_pose(&entry, sequence);
        fresh += usize::from(pose.is_fresh());
        (pose, driver.stamp_of(sequence))
    };
    assert_eq!(send().0.status, status::INITIALISING, "not found at the configured pose");
    // Detections the tracker must not apply: too old, of an unknown object, broken.
    let publisher = ipc::detections(&node, &config.detections_service).expect("service").publisher_builder().create();
    let publisher = publisher.expect("publisher");
    let truth = mrsmap::geometry::Pose::from_parts(
        nalgebra::Translation3::new(0.1923, 0.1253, 1.0402),
        nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(-0.13797, -0.25098, -0.79599, 0.53327)),
    );
    let (pose, frame_stamp_ns) = send();
    assert_eq!(pose.status, status::INITIALISING);
    let always = detection_mode::ALWAYS;
    let stale = ObjectDetection::new("teddy", &truth, frame_stamp_ns - 2_000_000_000, always);
    let stranger = ObjectDetection::new("bear", &truth, frame_stamp_ns, always);
    let broken = ObjectDetection { translation_m: [f64::NAN, 0.0, 1.0], ..stale };
    for d in [stale, stranger, broken] {
        publisher.send_copy(d).expect("sent");
    }
    assert_eq!(send().0.status, status::INITIALISING, "none of them applied");
    let seen = wait_for(&tracker_err, "a detection refused", 10).join("\n");
    assert!(seen.contains("its frame is 2.033 s older") && seen.contains("'bear' ignored"), "{seen}");
    // The detector client, as a robot's detector would send it (a process of its own),
    // for the frame sent last.
    let q = truth.rotation.quaternion();
    let t = truth.translation.vector;
    let pose: Vec<String> = [t.x, t.y, t.z, q.i, q.j, q.k, q.w].iter().map(|v| v.to_string()).collect();
    let stamp = send().1.to_string();
    let mut args = vec!["detect", "--object", "teddy", "--service", &config.detections_service];
    args.extend(["--poses", &config.poses_service, "--frame-stamp-ns", &stamp, "--pose"]);
    args.extend(pose.iter().map(String::as_str));
    let (ok, out) = run_while_sending(&args, &mut || {
        send();
    });
    assert!(ok, "{out}");
    let mm: f64 =
        out.split(" mm and").next().and_then(|s| s.rsplit(' ').next()).and_then(|v| v.parse().ok()).expect(&out);
    println!("{out}");
    assert!(out.contains("'teddy' tracked from the detection") && mm < 10.0, "{out}");
    assert!(send().0.is_fresh(), "tracked from then on");
    // A detection of an object being tracked changes nothing unless it says always.
    let (ok, out) = run_while_sending(&args, &mut || {
        send();
    });
    assert!(ok && out.contains("the detection was not needed"), "{out}");
    signal(&tracker.0, "TERM");
    let (code, out) = finish(tracker, 30);
    assert_eq!(code, Some(0), "{out}");
    let counts = "detections: 1 applied, 1 not needed (object tracked), 1 too old, 1 of unknown objects, 1 invalid";
    assert!(out.contains(counts), "{out}");
    // The replay of the recording: the detection applied before the same frame, so the
    // same frames tracked as live.
    let replayed = Command::new(mrsmap_bin())
        .args(["replay", "--input", path_str(&recorded), "--config", path_str(&config_path)])
        .output()
        .expect("replay runs");
    let stdout = String::from_utf8_lossy(&replayed.stdout);
    assert!(replayed.status.success(), "{stdout}{}", String::from_utf8_lossy(&replayed.stderr));
    let frames = format!("{sequence} frames paired");
    let tracking = format!("teddy: {fresh} frames tracking (0 held)");
    assert!(stdout.contains(&frames) && stdout.contains(&tracking), "{frames}, {tracking} in {stdout}");
    assert!(stdout.contains("detections recorded with the live run: 1 of 1 applied again"), "{stdout}");
}

#[test]
fn missing_or_corrupt_models_stop_the_tracker_at_start_with_a_clear_error() {
    let dir = temp_dir("bad-models");
    let config_path = write_tracker_config(&dir, "bad", "");
    let text = std::fs::read_to_string(&config_path).expect("config");
    let model = root().join("models/teddy.mrsm");
    let missing = text.replace(path_str(&model), "/no/such/teddy.mrsm");
    std::fs::write(&config_path, missing).expect("write");
    let out = mrsmap(&["track", "--config", path_str(&config_path)]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/no/such/teddy.mrsm") && err.contains("teddy"), "{err}");
    let bytes = std::fs::read(&model).expect("model");
    let cut = dir.join("cut.mrsm");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write");
    std::fs::write(&config_path, text.replace(path_str(&model), path_str(&cut))).expect("write");
    let out = mrsmap(&["track", "--config", path_str(&config_path)]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("truncated") && err.contains("cut.mrsm"), "{err}");
}

#[test]
fn a_recording_that_cannot_be_written_is_named_at_start() {
    // The file exists and opens, but every write fails (a full disk): the tracker says
    // which recording it could not start instead of the MCAP crate's bare I/O error.
    // (`--force`: the partial file stands where a crash would leave one, which is
    // otherwise kept.)
    let dir = temp_dir("record-full");
    let config_path = write_tracker_config(&dir, "full", "");
    let partial = dir.join("run.mcap.partial");
    let _ = std::fs::remove_file(&partial);
    std::os::unix::fs::symlink("/dev/full", &partial).expect("symlink");
    let record = dir.join("run.mcap");
    let out = Command::new(mrsmap_bin())
        .args([
            "track",
            "--config",
            path_str(&config_path),
            "--record",
            path_str(&record),
            "--force",
            "--idle-timeout",
            "1",
        ])
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains(&format!("starting the recording {}", partial.display())), "{err}");
}

#[test]
fn camera_replays_mcap_and_the_tracker_records_what_it_receives() {
    let dir = temp_dir("mcap-live");
    let recording = dir.join("teddy.mcap");
    let out = Command::new(mrsmap_bin())
        .args(["convert", "tum-to-mcap", path_str(&teddy_clip()), "--out", path_str(&recording)])
        .output()
        .expect("convert runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let config_path = write_tracker_config(&dir, "mcaplive", "");
    let config = read_tracker_config(&config_path).expect("config");
    let recorded = dir.join("recorded.mcap");
    let (tracker, tracker_err) = start(&["track", "--config", path_str(&config_path), "--record", path_str(&recorded)]);
    wait_for(&tracker_err, "ready", 60);
    let (client, client_err) = start(&["poses", "--service", &config.poses_service, "--count", "8", "--timeout", "30"]);
    wait_for(&client_err, "reading", 30);
    let rate = camera_hz(10);
    let (camera, _) =
        start(&["camera", "--mcap", path_str(&recording), "--service", &config.camera_service, "--rate", &rate]);
    assert_eq!(finish(camera, 60).0, Some(0), "the driver sends the 8 frames of the recording and exits");
    let (code, out) = finish(client, 60);
    assert_eq!(code, Some(0), "client: {out}");
    assert!(out.contains("8 tracking"), "{out}");
    signal(&tracker.0, "INT");
    let (code, out) = finish(tracker, 30);
    assert_eq!(code, Some(0), "clean shutdown on SIGINT: {out}");
    assert!(!dir.join("recorded.mcap.partial").exists(), "the recording was finished");
    // The recording holds the 8 frames and the tracker's poses: replaying it tracks the
    // same frames, and its pose topics hold one pose per frame.
    let replayed = Command::new(mrsmap_bin())
        .args(["replay", "--input", path_str(&recorded), "--config", path_str(&config_path)])
        .output()
        .expect("replay runs");
    let stdout = String::from_utf8_lossy(&replayed.stdout);
    assert!(replayed.status.success(), "{stdout}{}", String::from_utf8_lossy(&replayed.stderr));
    assert!(stdout.contains("8 frames paired") && stdout.contains("8 frames tracking"), "{stdout}");
    let mut poses = mrsmap::io::mcap_source::McapSource::open(&recorded, &["/mrsmap/teddy/pose"]).expect("opens");
    let mut count = 0;
    while let Some(m) = poses.next_message_with(|_| ()) {
        m.expect("pose message");
        count += 1;
    }
    assert_eq!(count, 8, "one recorded pose per tracked frame");
    // With them the transforms a viewer places the model by, and the model once.
    let source = mrsmap::io::mcap_source::McapSource::open(&recorded, &["/tf"]).expect("opens");
    assert_eq!(source.message_count("/tf"), Some(8), "a transform per tracked frame");
    assert_eq!(source.message_count("/mrsmap/teddy/model"), Some(1), "the model, once");
}

#[test]
fn a_tracker_restarts_while_clients_hold_its_poses() {
    // A client keeps the pose blackboard after its tracker stops (iceoryx2 removes a
    // service with its last user). A tracker that exited reopens it, and a client that
    // never lets go keeps reading; a second tracker on the same poses is refused; one
    // that restarts after a crash waits until the clients let go (`mrsmap poses` does).
    let dir = temp_dir("restart");
    let config_path = write_tracker_config(&dir, "restart", "");
    let config = read_tracker_config(&config_path).expect("config");
    let track = || start(&["track", "--config", path_str(&config_path)]);
    let (first, first_err) = track();
    wait_for(&first_err, "ready", 60);
    let driver = TestDriver::new(&config.camera_service);
    let node = ipc::node("test_reader").expect("node");
    let poses = ipc::open_poses(&node, &config.poses_service).expect("the tracker created the blackboard");
    let reader = poses.reader_builder().create().expect("reader");
    let entry = reader.entry::<ObjectPose>(&0).expect("object 0");
    driver.send(1, |_| {});
    assert_eq!(read_pose(&entry, 1).status, status::TRACKING);
    let (second, _) = track();
    let (code, _) = finish(second, 60);
    assert_eq!(code, Some(1), "a second tracker on the same poses is refused");
    signal(&first.0, "INT");
    assert_eq!(finish(first, 30).0, Some(0));
    // Meanwhile the blackboard has no writer: a client does not take it for a tracker.
    let out = Command::new(mrsmap_bin())
        .args(["poses", "--service", &config.poses_service, "--timeout", "1"])
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("no tracker publishes") && err.contains("a tracker that stopped"), "{err}");
    // Restarted while this client holds the blackboard: the same entry carries its poses.
    let (restarted, restarted_err) = track();
    wait_for(&restarted_err, "ready", 60);
    assert_eq!(entry.get().frame_send_stamp_ns, 0, "the earlier tracker's last pose is not offered as new");
    driver.send(2, |_| {});
    assert_eq!(read_pose(&entry, 2).status, status::TRACKING, "the client reads the restarted tracker");
    // A crash: its entry stays claimed until no client holds the blackboard.
    let (client, client_err) = start(&["poses", "--service", &config.poses_service, "--count", "2", "--timeout", "60"]);
    wait_for(&client_err, "reading", 30);
    signal(&restarted.0, "KILL");
    drop(restarted);
    // This process holds the blackboard too until the tracker started after the crash has
    // said that it waits: the client may let go before that tracker even opens it (it does
    // once the crashed tracker's node is cleaned up), and the tracker would then meet no
    // entries of the crashed one.
    let (after_crash, after_crash_err) = track();
    wait_for(&after_crash_err, "crashed", 60);
    drop((entry, reader, poses, node));
    wait_for(&after_crash_err, "ready", 60);
    wait_for(&client_err, "the tracker stopped", 30);
    wait_for(&client_err, "reading", 30);
    driver.send(3, |_| {});
    let (code, out) = finish(client, 60);
    assert_eq!(code, Some(0), "{out}");
    assert!(out.contains("poses: 2 messages") && out.contains("2 tracking"), "{out}");
    signal(&after_crash.0, "INT");
    assert_eq!(finish(after_crash, 30).0, Some(0));
}

#[test]
fn a_driver_of_the_other_image_size_is_pointed_out() {
    // The tracker listens for QVGA, the driver sends VGA: no frame arrives, and the
    // tracker says why instead of only that none came.
    let dir = temp_dir("other-size");
    let text = tracker_config_text("othersize", "").replace("[camera]\n", "[camera]\nsize = \"qvga\"\n");
    let config_path = dir.join("tracker.toml");
    std::fs::write(&config_path, text).expect("write config");
    let config = read_tracker_config(&config_path).expect("config");
    let (tracker, tracker_err) = start(&["track", "--config", path_str(&config_path), "--idle-timeout", "10"]);
    wait_for(&tracker_err, "ready", 60);
    let _camera = start_looping_driver(&config.camera_service, "30");
    let seen = wait_for(&tracker_err, "no frame", 30);
    let line = seen.last().expect("the line");
    assert!(line.contains("/rgbd/vga exists") && line.contains("--qvga"), "{line}");
    signal(&tracker.0, "INT");
    assert_eq!(finish(tracker, 30).0, Some(0));
}

#[test]
fn a_client_given_an_impossible_service_name_says_so_at_once() {
    // Not "no tracker publishes there" after the whole timeout: no tracker ever could.
    let started = std::time::Instant::now();
    let out = Command::new(mrsmap_bin())
        .args(["poses", "--service", &"a".repeat(300), "--timeout", "30"])
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("service name") && err.contains("ExceedsMaximumLength"), "{err}");
    assert!(started.elapsed() < Duration::from_secs(10), "it waited {:?}", started.elapsed());
}
