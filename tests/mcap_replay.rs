//! MCAP recordings: reading files of an independent writer (Python `mcap-ros2-support`,
//! `mcap-protobuf-support` with the Foxglove schemas, raw and compressed images:
//! tests/data/python_*.mcap, made by scripts/make_mcap_fixture.py), conversion, replay (same poses as the dataset run,
//! byte-identical output at 1 and 2 threads) and bad recordings.

mod common;

use common::*;
use mrsmap::app::convert::{ConvertJob, run as convert};
use mrsmap::app::replay::{ReplayJob, run as replay};
use mrsmap::io::mcap_source::ReadMode;
use mrsmap::io::mcap_write::{DEFAULT_CHUNK_BYTES, DepthEncoding, FrameChannels, McapFile};
use mrsmap::io::recording::{RecordingError, RecordingReader, RecordingTopics};
use mrsmap::io::ros2::{CameraInfo, Header, Image, RegionOfInterest, Time};
use mrsmap::io::tracker_config::read_tracker_config;
use std::path::{Path, PathBuf};

const W: usize = 64;
const H: usize = 48;

fn expected_rgb(i: usize) -> Vec<u8> {
    let mut v = Vec::new();
    for y in 0..H {
        for u in 0..W {
            v.extend([((u * 7 + y * 3 + i) % 256) as u8, ((u + 5 * y) % 256) as u8, ((40 * i + u) % 256) as u8]);
        }
    }
    v
}

fn expected_depth_mm(i: usize) -> Vec<u16> {
    (0..H).flat_map(|y| (0..W).map(move |u| (500 + 10 * u + y + i) as u16)).collect()
}

fn expected_depth_stamp_ns(i: usize) -> u64 {
    1_000_000_000 + i as u64 * 1_000_000_000 / 30
}

fn alt_topics() -> RecordingTopics {
    RecordingTopics { color: "/alt/color".into(), depth: "/alt/depth".into(), camera_info: "/alt/camera_info".into() }
}

/// Reads every frame of a fixture and checks pixels, stamps and calibration.
fn check_fixture(path: &Path, topics: RecordingTopics, depth_units_per_mm: u16) {
    let mut reader = RecordingReader::open(path, topics, None).expect("opens");
    assert_eq!(reader.mode(), ReadMode::Indexed);
    let mut i = 0;
    while let Some(frame) = reader.next_frame().expect("decodes") {
        assert_eq!(frame.stamp_ns, expected_depth_stamp_ns(i), "frame {i} has the depth stamp");
        assert_eq!((frame.camera.width, frame.camera.height), (W as u32, H as u32));
        let k = frame.camera.intrinsics;
        assert_eq!((k.fx, k.fy, k.cx, k.cy), (52.5, 53.0, 31.5, 23.5));
        assert_eq!(frame.rgb, &expected_rgb(i)[..], "colour of frame {i}");
        let depth: Vec<u16> = expected_depth_mm(i).iter().map(|d| d * depth_units_per_mm).collect();
        assert_eq!(frame.depth, &depth[..], "depth of frame {i}");
        let metres = f64::from(frame.depth[0]) * frame.camera.depth_scale_m;
        assert!((metres - f64::from(500 + i as u16) * 1e-3).abs() < 1e-9, "depth scale: {metres}");
        i += 1;
    }
    assert_eq!(i, 3, "all frames of {}", path.display());
    assert!(reader.damage().is_none());
    assert_eq!(reader.stats().unpaired, 0);
    // The same frames handed over without a copy, into one frame whose buffers go back
    // and forth with the reader's.
    let mut reader = RecordingReader::open(path, reader.topics().clone(), None).expect("opens");
    let mut owned = mrsmap::frame::OwnedFrame::default();
    let mut n = 0;
    while reader.next_frame_into(&mut owned).expect("decodes") {
        assert_eq!(owned.stamp_ns, expected_depth_stamp_ns(n));
        assert_eq!(owned.rgb, expected_rgb(n), "colour of frame {n}, handed over");
        let depth: Vec<u16> = expected_depth_mm(n).iter().map(|d| d * depth_units_per_mm).collect();
        assert_eq!(owned.depth, depth, "depth of frame {n}, handed over");
        n += 1;
    }
    assert_eq!(n, 3);
}

#[test]
fn reads_ros2_recordings_of_the_python_writer() {
    check_fixture(&root().join("tests/data/python_ros2.mcap"), RecordingTopics::default(), 1);
    // bgr8 colour and 32FC1 depth in metres (stored at 0.2 mm, so 5 units per mm).
    check_fixture(&root().join("tests/data/python_ros2.mcap"), alt_topics(), 5);
}

#[test]
fn reads_foxglove_raw_images_of_the_python_writer() {
    check_fixture(&root().join("tests/data/python_foxglove.mcap"), RecordingTopics::default(), 1);
}

#[test]
fn reads_foxglove_compressed_images_of_the_python_writer() {
    // PNG colour and 16-bit PNG depth: lossless, so the same pixels as the raw fixture.
    check_fixture(&root().join("tests/data/python_foxglove_compressed.mcap"), RecordingTopics::default(), 1);
}

#[test]
fn reads_ros2_compressed_images_of_the_python_writer() {
    let path = root().join("tests/data/python_ros2_compressed.mcap");
    for (depth_topic, metres) in
        [("/camera/depth/image_raw/compressedDepth", false), ("/alt/depth/compressedDepth", true)]
    {
        let topics = RecordingTopics {
            color: "/camera/color/image_raw/compressed".into(),
            depth: depth_topic.into(),
            camera_info: "/camera/color/camera_info".into(),
        };
        let mut reader = RecordingReader::open(&path, topics, None).expect("opens");
        let mut i = 0;
        while let Some(frame) = reader.next_frame().expect("decodes") {
            assert_eq!(frame.stamp_ns, expected_depth_stamp_ns(i), "frame {i} has the depth stamp");
            assert_eq!((frame.camera.width, frame.camera.height), (W as u32, H as u32));
            // JPEG (quality 95, no chroma subsampling) is lossy: close, and in RGB order (a
            // swap of red and blue would differ by ~100 on average).
            let expected = expected_rgb(i);
            let diffs: Vec<u32> = frame.rgb.iter().zip(&expected).map(|(a, b)| u32::from(a.abs_diff(*b))).collect();
            let mean = diffs.iter().sum::<u32>() as f64 / diffs.len() as f64;
            assert!(mean < 3.0 && diffs.iter().all(|&d| d <= 40), "JPEG colour of frame {i}: mean error {mean}");
            for (k, (&got, want_mm)) in frame.depth.iter().zip(expected_depth_mm(i)).enumerate() {
                let got_mm = f64::from(got) * frame.camera.depth_scale_m * 1e3;
                // 32FC1: quantised inverse depth (0.1 mm steps at 1 m), then 0.2 mm units.
                let tolerance = if metres { 0.5 } else { 1e-9 };
                assert!((got_mm - f64::from(want_mm)).abs() <= tolerance, "depth {k} of frame {i}: {got_mm} mm");
            }
            i += 1;
        }
        assert_eq!(i, 3, "all frames with depth from {depth_topic}");
    }
}

fn convert_clip(dir: &Path, depth_encoding: DepthEncoding) -> PathBuf {
    convert_clip_chunked(dir, depth_encoding, DEFAULT_CHUNK_BYTES, "teddy.mcap")
}

fn convert_job(out: PathBuf, depth_encoding: DepthEncoding, chunk_bytes: u64) -> ConvertJob {
    ConvertJob {
        dataset: teddy_clip(),
        camera: None,
        out,
        force: false,
        depth_encoding,
        compression: mcap::Compression::Zstd,
        chunk_bytes,
        topics: RecordingTopics::default(),
        first_frame: 0,
        max_frames: None,
        stop: Default::default(),
    }
}

fn convert_clip_chunked(dir: &Path, depth_encoding: DepthEncoding, chunk_bytes: u64, name: &str) -> PathBuf {
    let out = dir.join(name);
    let s = convert(&convert_job(out.clone(), depth_encoding, chunk_bytes)).expect("converts");
    assert_eq!((s.written, s.skipped, s.interrupted), (8, 0, None));
    out
}

fn replay_job(input: &Path, out: Option<PathBuf>, trajectory: Option<PathBuf>) -> ReplayJob {
    ReplayJob {
        input: input.to_path_buf(),
        out,
        force: false,
        trajectory,
        topics: RecordingTopics::default(),
        camera: None,
        groundtruth: None,
        every: 1,
        qvga: false,
        max_frames: None,
        stop: Default::default(),
    }
}

fn config_with_threads(dir: &Path, threads: usize) -> mrsmap::io::tracker_config::TrackerConfig {
    let path = dir.join(format!("tracker{threads}.toml"));
    let text = tracker_config_text("replay", "").replace("threads = 2", &format!("threads = {threads}"));
    std::fs::write(&path, text).expect("write config");
    read_tracker_config(&path).expect("config")
}

#[test]
fn replay_matches_the_dataset_run_and_is_byte_identical_at_any_thread_count() {
    let dir = temp_dir("mcap-replay");
    let recording = convert_clip(&dir, DepthEncoding::M32);
    let mut outputs = Vec::new();
    for threads in [1, 2] {
        let config = config_with_threads(&dir, threads);
        let out = dir.join(format!("poses{threads}.mcap"));
        let traj = dir.join(format!("traj{threads}.txt"));
        let s = replay(&config, &replay_job(&recording, Some(out.clone()), Some(traj.clone()))).expect("replays");
        assert_eq!(s.tracked_frames, 8);
        assert_eq!(s.objects[0].1[0], 8, "tracking on every frame");
        outputs.push((std::fs::read(&out).expect("poses"), std::fs::read_to_string(&traj).expect("trajectory")));
    }
    assert!(outputs[0].0 == outputs[1].0, "the pose files differ between 1 and 2 threads");
    // 32FC1 keeps TUM's depth units exactly: the same poses as tracking the dataset.
    let config = config_with_threads(&dir, 2);
    let tracked = mrsmap::app::track_dataset::run(&config, &job_template(&dir)).expect("tracks the dataset");
    // With the clip's ground truth, the replay reports the accuracy the dataset run does.
    let with_truth =
        ReplayJob { groundtruth: Some(teddy_clip().join("groundtruth.txt")), ..replay_job(&recording, None, None) };
    let replayed = replay(&config, &with_truth).expect("replays with ground truth");
    let (a, b) = (&replayed.accuracy[0], &tracked.objects[0].accuracy);
    let (ate_a, ate_b) = (a.ate.expect("ATE of the replay"), b.ate.expect("ATE of the dataset run"));
    assert_eq!(ate_a.count, 8);
    assert!((ate_a.median - ate_b.median).abs() < 1e-9 && (ate_a.max - ate_b.max).abs() < 1e-9);
    for (x, y) in [(a.covariance, b.covariance), (a.covariance_change, b.covariance_change)] {
        let (x, y) = (x.expect("covariance figures"), y.expect("covariance figures"));
        assert_eq!(x.count, y.count);
        assert!((x.median_nees / y.median_nees - 1.0).abs() < 1e-6, "{x:?} against {y:?}");
    }
    assert!(replay(&config, &replay_job(&recording, None, None)).expect("replays").accuracy.is_empty());
    // A ground truth of another time compares nothing (the summary warns).
    let truth = std::fs::read_to_string(teddy_clip().join("groundtruth.txt")).expect("ground truth");
    let shifted: String = truth
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split_once(' ').map(|(t, rest)| format!("{} {rest}\n", t.parse::<f64>().expect("stamp") + 1000.0)))
        .collect::<Option<String>>()
        .expect("lines");
    std::fs::write(dir.join("later.txt"), shifted).expect("write");
    let other = ReplayJob { groundtruth: Some(dir.join("later.txt")), ..replay_job(&recording, None, None) };
    let a = replay(&config, &other).expect("replays").accuracy[0];
    assert_eq!((a.compared, a.ate, a.covariance), (0, None, None));
    assert_eq!(replayed.accuracy[0].compared, 8);
    let body = |t: &str| t.lines().filter(|l| !l.starts_with('#')).map(str::to_string).collect::<Vec<_>>();
    let from_dataset = std::fs::read_to_string(dir.join("dataset.txt")).expect("trajectory");
    assert_eq!(body(&outputs[0].1), body(&from_dataset));
    assert_eq!(body(&from_dataset).len(), 8);
    // At QVGA (halved on read) too.
    let qvga_traj = dir.join("qvga.txt");
    let job = ReplayJob { qvga: true, ..replay_job(&recording, None, Some(qvga_traj.clone())) };
    assert_eq!(replay(&config, &job).expect("replays at QVGA").objects[0].1[0], 8);
    let dataset_job = mrsmap::app::track_dataset::TrackDatasetJob {
        qvga: true,
        trajectory: Some(dir.join("dataset_qvga.txt")),
        ..job_template(&dir)
    };
    mrsmap::app::track_dataset::run(&config, &dataset_job).expect("tracks the dataset at QVGA");
    let read = |p: PathBuf| body(&std::fs::read_to_string(p).expect("trajectory"));
    assert_eq!(read(qvga_traj), read(dir.join("dataset_qvga.txt")));
}

/// Every message of an MCAP file: topic, log time, data.
fn messages(path: &Path) -> Vec<(String, u64, Vec<u8>)> {
    let bytes = std::fs::read(path).expect("mcap");
    mcap::MessageStream::new(&bytes)
        .expect("mcap")
        .map(|m| m.expect("message"))
        .map(|m| (m.channel.topic.clone(), m.log_time, m.data.into_owned()))
        .collect()
}

#[test]
fn the_replay_places_the_model_in_the_object_frame_on_tf() {
    use mrsmap::io::ros2::{PointCloud2, PoseWithCovarianceStamped, TfMessage, decode};
    let dir = temp_dir("mcap-tf");
    let recording = convert_clip(&dir, DepthEncoding::M32);
    let config = config_with_threads(&dir, 2);
    let out = dir.join("poses.mcap");
    replay(&config, &replay_job(&recording, Some(out.clone()), None)).expect("replays");
    let all = messages(&out);
    let of = |topic: &'static str| all.iter().filter(move |(t, ..)| t == topic);
    let poses: Vec<(u64, PoseWithCovarianceStamped)> =
        of("/mrsmap/teddy/pose").map(|(_, at, d)| (*at, decode(d).expect("pose"))).collect();
    let tf: Vec<(u64, TfMessage)> = of("/tf").map(|(_, at, d)| (*at, decode(d).expect("tf"))).collect();
    assert_eq!((poses.len(), tf.len()), (8, 8), "a transform with every published pose");
    for ((at, pose), (tf_at, tf)) in poses.iter().zip(&tf) {
        assert_eq!(at, tf_at);
        let [t] = &tf.transforms[..] else { panic!("one object, one transform: {tf:?}") };
        assert_eq!(
            (t.header.frame_id.as_str(), t.child_frame_id.as_str()),
            ("camera_color_optical_frame", "mrsmap/teddy")
        );
        assert_eq!(t.header.stamp, pose.header.stamp);
        let p = &pose.pose.pose;
        let r = &t.transform;
        assert_eq!([r.translation.x, r.translation.y, r.translation.z], [p.position.x, p.position.y, p.position.z]);
        assert_eq!(r.rotation, p.orientation);
    }
    // The model, once, with the first frame, in the object's frame: its finest surfels.
    let clouds: Vec<(u64, PointCloud2)> =
        of("/mrsmap/teddy/model").map(|(_, at, d)| (*at, decode(d).expect("cloud"))).collect();
    let [(at, cloud)] = &clouds[..] else { panic!("one model cloud, {} written", clouds.len()) };
    assert_eq!(*at, poses[0].0);
    assert_eq!(cloud.header.frame_id, "mrsmap/teddy");
    let model = mrsmap::model::load(&config.objects[0].model).expect("model");
    let leaves = model.map.leaf_surfels();
    assert!(leaves.len() > 1000, "{} surfels", leaves.len());
    assert_eq!((cloud.height, cloud.width, cloud.point_step), (1, leaves.len() as u32, 16));
    assert_eq!(cloud.data.len(), 16 * leaves.len());
    let names: Vec<(&str, u32, u8)> = cloud.fields.iter().map(|f| (f.name.as_str(), f.offset, f.datatype)).collect();
    assert_eq!(names, [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("rgb", 12, 7)]);
    for (point, &s) in cloud.data.chunks_exact(16).zip(&leaves) {
        let f = |i: usize| f32::from_le_bytes(point[4 * i..4 * i + 4].try_into().expect("4 bytes"));
        let mean = model.map.surfels()[s as usize].mean;
        assert_eq!([f(0), f(1), f(2)], [mean.x, mean.y, mean.z]);
        assert_eq!(point[15], 0, "rgb packed as b, g, r, 0");
    }
    let grey = cloud.data.chunks_exact(16).filter(|p| p[12] == p[13] && p[13] == p[14]).count();
    assert!(grey < leaves.len() / 2, "the model's colours: {grey} of {} points grey", leaves.len());
}

/// The chunks of an MCAP file, from its summary.
fn chunk_count(path: &Path) -> usize {
    let bytes = std::fs::read(path).expect("recording");
    mcap::Summary::read(&bytes).expect("summary").expect("indexed").chunk_indexes.len()
}

#[test]
fn the_chunk_size_sets_the_frames_per_chunk_and_the_poses_do_not_depend_on_it() {
    let dir = temp_dir("mcap-chunks");
    // The default (1 MiB): a VGA frame (1.5 MB of images) fills a chunk; 4 MiB chunks (the
    // layout of `ros2 bag record`'s `zstd_small` preset) hold two or three.
    let small = convert_clip(&dir, DepthEncoding::Mm16);
    let large = convert_clip_chunked(&dir, DepthEncoding::Mm16, 4 << 20, "large.mcap");
    let (small_chunks, large_chunks) = (chunk_count(&small), chunk_count(&large));
    // A size the replay could not read back is refused before anything is written.
    for bad in [0, mrsmap::io::mcap_write::MAX_CHUNK_BYTES + 1] {
        let e = convert(&convert_job(dir.join("bad.mcap"), DepthEncoding::Mm16, bad)).expect_err("refused").to_string();
        assert!(e.contains("chunk size"), "{e}");
        assert!(!dir.join("bad.mcap").exists());
    }
    assert!((8..=9).contains(&small_chunks), "{small_chunks} chunks for 8 frames at the default size");
    assert!((3..=4).contains(&large_chunks), "{large_chunks} chunks for 8 frames of 4 MiB chunks");
    let config = config_with_threads(&dir, 2);
    let poses = |input: &Path, name: &str| {
        let traj = dir.join(name);
        let s = replay(&config, &replay_job(input, None, Some(traj.clone()))).expect("replays");
        assert_eq!(s.objects[0].1[0], 8, "tracking on every frame");
        let text = std::fs::read_to_string(&traj).expect("trajectory");
        text.lines().filter(|l| !l.starts_with('#')).map(str::to_string).collect::<Vec<_>>()
    };
    let from_small = poses(&small, "small.txt");
    assert_eq!(from_small.len(), 8);
    assert_eq!(from_small, poses(&large, "large.txt"), "the same poses from either layout");
}

fn job_template(dir: &Path) -> mrsmap::app::track_dataset::TrackDatasetJob {
    mrsmap::app::track_dataset::TrackDatasetJob {
        dataset: teddy_clip(),
        camera: fr3_camera_file(),
        first_frame: 0,
        every: 1,
        max_frames: None,
        qvga: false,
        start_at_ground_truth: false,
        detector: None,
        trajectory: Some(dir.join("dataset.txt")),
        overlay: None,
        stop: Default::default(),
    }
}

/// Writes a recording of `frames` synthetic frames with a custom depth message.
fn write_custom(path: &Path, with_info: bool, depth: impl Fn(&mut Vec<u8>) -> (u32, u32, &'static str)) {
    let mut file = McapFile::create(path, mcap::Compression::Lz4, DEFAULT_CHUNK_BYTES).expect("create");
    let t = RecordingTopics::default();
    let image = mrsmap::io::ros2::image_schema();
    let c = file.add_ros2_channel(&t.color, "sensor_msgs/msg/Image", &image).expect("channel");
    let d = file.add_ros2_channel(&t.depth, "sensor_msgs/msg/Image", &image).expect("channel");
    let info =
        file.add_ros2_channel(&t.camera_info, "sensor_msgs/msg/CameraInfo", &mrsmap::io::ros2::camera_info_schema());
    let info = info.expect("channel");
    let header = |ns| Header { stamp: Time::from_ns(ns), frame_id: "cam".into() };
    let rgb = expected_rgb(0);
    let mut bytes = Vec::new();
    for i in 0..3u64 {
        let ns = 1_000_000_000 + i * 33_000_000;
        if with_info {
            let k = [50.0, 0.0, 32.0, 0.0, 50.0, 24.0, 0.0, 0.0, 1.0];
            let m = CameraInfo {
                header: header(ns),
                height: H as u32,
                width: W as u32,
                distortion_model: "plumb_bob".into(),
                d: vec![0.0; 5],
                k,
                r: [0.0; 9],
                p: [0.0; 12],
                binning_x: 0,
                binning_y: 0,
                roi: RegionOfInterest::default(),
            };
            file.write_cdr(info, ns, &m).expect("write");
        }
        let colour = Image {
            header: header(ns),
            height: H as u32,
            width: W as u32,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: 3 * W as u32,
            data: &rgb,
        };
        file.write_cdr(c, ns, &colour).expect("write");
        let (width, height, encoding) = depth(&mut bytes);
        let step = (bytes.len() as u32).checked_div(height).unwrap_or(0);
        let m =
            Image { header: header(ns), height, width, encoding: encoding.into(), is_bigendian: 0, step, data: &bytes };
        file.write_cdr(d, ns, &m).expect("write");
    }
    file.finish().expect("finish");
}

fn mm_depth(bytes: &mut Vec<u8>, w: usize, h: usize) {
    bytes.clear();
    bytes.extend((0..w * h).flat_map(|_| 800u16.to_le_bytes()));
}

fn first_error(path: &Path, camera: Option<mrsmap::geometry::CameraModel>) -> RecordingError {
    let mut reader = RecordingReader::open(path, RecordingTopics::default(), camera).expect("opens");
    loop {
        match reader.next_frame() {
            Ok(Some(_)) => {}
            Ok(None) => panic!("{} read without error", path.display()),
            Err(e) => return e,
        }
    }
}

#[test]
fn bad_recordings_give_errors_naming_topic_and_message() {
    let dir = temp_dir("mcap-bad");
    let unknown = dir.join("unknown.mcap");
    write_custom(&unknown, true, |b| {
        b.clear();
        b.resize(W * H * 2, 0);
        (W as u32, H as u32, "yuv422")
    });
    let e = first_error(&unknown, None).to_string();
    assert!(e.contains("topic /camera/depth/image_raw, message 0") && e.contains("'yuv422'"), "{e}");

    // A topic the recording does not have is said at once, with the topics it has.
    let topics = RecordingTopics { color: "/camera/rgb/image_color".into(), ..RecordingTopics::default() };
    let e = RecordingReader::open(&unknown, topics, None).expect_err("no such topic");
    let text = e.to_string();
    assert!(matches!(e, RecordingError::NoSuchTopic { what: "colour", .. }), "{text}");
    assert!(
        text.contains("--color-topic") && text.contains("/camera/color/image_raw (sensor_msgs/msg/Image)"),
        "{text}"
    );

    let no_info = dir.join("no_info.mcap");
    write_custom(&no_info, false, |b| {
        mm_depth(b, W, H);
        (W as u32, H as u32, "16UC1")
    });
    let e = first_error(&no_info, None);
    assert!(matches!(e, RecordingError::NoCalibration { index: 0, .. }), "{e}");
    assert!(e.to_string().contains("/camera/color/camera_info"), "{e}");
    // A camera file instead of the calibration topic.
    let mut camera = vga();
    (camera.width, camera.height) = (W as u32, H as u32);
    let mut reader = RecordingReader::open(&no_info, RecordingTopics::default(), Some(camera)).expect("opens");
    let frame = reader.next_frame().expect("reads").expect("a frame");
    assert_eq!(frame.camera.depth_scale_m, 1e-3, "16UC1 is in millimetres");

    let mismatched = dir.join("mismatched.mcap");
    write_custom(&mismatched, true, |b| {
        mm_depth(b, W / 2, H / 2);
        (W as u32 / 2, H as u32 / 2, "16UC1")
    });
    let e = first_error(&mismatched, None).to_string();
    assert!(
        e.contains("topic /camera/depth/image_raw, message 0") && e.contains("32×24") && e.contains("64×48"),
        "{e}"
    );

    let short = dir.join("short.mcap");
    write_custom(&short, true, |b| {
        mm_depth(b, W, H / 2);
        (W as u32, H as u32, "16UC1")
    });
    let e = first_error(&short, None).to_string();
    assert!(e.contains("message 0") && e.contains("needs"), "{e}");

    let not_mcap = dir.join("not.mcap");
    std::fs::write(&not_mcap, b"this is not a recording").expect("write");
    let e = RecordingReader::open(&not_mcap, RecordingTopics::default(), None).expect_err("not MCAP").to_string();
    assert!(e.contains("not.mcap"), "{e}");
}

#[test]
fn a_truncated_recording_replays_up_to_the_damage() {
    let dir = temp_dir("mcap-truncated");
    let recording = convert_clip(&dir, DepthEncoding::Mm16);
    let bytes = std::fs::read(&recording).expect("read");
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).expect("write");
    let mut reader = RecordingReader::open(&cut, RecordingTopics::default(), None).expect("opens");
    assert_eq!(reader.mode(), ReadMode::Streamed, "no summary: streamed");
    let mut frames = 0;
    while reader.next_frame().expect("frames before the damage decode").is_some() {
        frames += 1;
    }
    assert!((1..8).contains(&frames), "{frames} frames before the damage");
    let damage = reader.damage().expect("damage reported");
    assert!(damage.messages_before >= 3 * frames as u64, "{damage:?}");

    // Through the command line: exit 0, the frames before the damage tracked, a warning.
    let config = write_tracker_config(&dir, "truncated", "");
    let out = std::process::Command::new(mrsmap_bin())
        .args(["replay", "--input"])
        .arg(&cut)
        .arg("--config")
        .arg(&config)
        .arg("--trajectory")
        .arg(dir.join("cut.txt"))
        .output()
        .expect("runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("damaged") && stdout.contains(&format!("{frames} tracked")), "{stdout}");
    let lines = std::fs::read_to_string(dir.join("cut.txt")).expect("trajectory");
    assert_eq!(lines.lines().filter(|l| !l.starts_with('#')).count(), frames);
    // Streamed, a mistyped topic cannot be found out before reading: it is said after.
    let out = std::process::Command::new(mrsmap_bin())
        .args(["replay", "--color-topic", "/nope", "--input"])
        .arg(&cut)
        .arg("--config")
        .arg(&config)
        .output()
        .expect("runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("warning: no message on the colour topic /nope (named by --color-topic)"), "{stdout}");
}

#[test]
fn a_recording_written_by_mrsmap_reads_back() {
    let dir = temp_dir("mcap-roundtrip");
    let mut camera = vga();
    (camera.width, camera.height, camera.depth_scale_m) = (W as u32, H as u32, 1e-3);
    // A pinhole, plumb_bob and rational_polynomial CameraInfo each come back as written.
    let rational = [0.45, -2.5, 0.0007, -0.0003, 1.4, 0.33, -2.35, 1.35];
    let plumb_bob = [0.1, -0.2, 0.001, 0.002, 0.05, 0.0, 0.0, 0.0];
    for (i, distortion) in [mrsmap::geometry::NO_DISTORTION, plumb_bob, rational].into_iter().enumerate() {
        let path = dir.join(format!("frames{i}.mcap"));
        let mut file = McapFile::create(&path, mcap::Compression::Zstd, DEFAULT_CHUNK_BYTES).expect("create");
        let t = RecordingTopics::default();
        let channels =
            FrameChannels::add(&mut file, [&t.color, &t.depth, &t.camera_info], DepthEncoding::Mm16).expect("add");
        let camera = mrsmap::geometry::CameraModel { distortion, ..camera };
        let rgb = expected_rgb(1);
        let depth = expected_depth_mm(1);
        let frame = mrsmap::frame::RgbdFrame::new(2_000_000_000, camera, &rgb, &depth).expect("frame");
        channels.write_frame(&mut file, &frame, 1_990_000_000, &mut Vec::new()).expect("write");
        file.finish().expect("finish");
        let mut reader = RecordingReader::open(&path, t, None).expect("opens");
        let back = reader.next_frame().expect("reads").expect("a frame");
        assert_eq!((back.stamp_ns, back.rgb, back.depth), (frame.stamp_ns, frame.rgb, frame.depth));
        assert_eq!(back.camera, frame.camera);
    }
}

#[test]
fn a_corrupt_chunk_in_an_indexed_recording_is_skipped_and_the_rest_replayed() {
    let dir = temp_dir("mcap-corrupt");
    let recording = convert_clip(&dir, DepthEncoding::Mm16);
    let mut bytes = std::fs::read(&recording).expect("read");
    // Overwrite a stretch in the middle of the data section; the summary stays intact.
    let middle = bytes.len() / 2;
    bytes[middle..middle + 4096].fill(0xA5);
    let bad = dir.join("bad.mcap");
    std::fs::write(&bad, &bytes).expect("write");
    let mut reader = RecordingReader::open(&bad, RecordingTopics::default(), None).expect("opens");
    assert_eq!(reader.mode(), ReadMode::Indexed);
    let mut stamps = Vec::new();
    while let Some(frame) = reader.next_frame().expect("the intact chunks decode") {
        stamps.push(frame.stamp_ns);
    }
    println!("{} frames; skipped {:?}", stamps.len(), reader.skipped_chunks());
    assert_eq!(reader.skipped_chunks().len(), 1, "one damaged chunk");
    assert!(reader.damage().is_none());
    assert!((1..8).contains(&stamps.len()), "{} frames", stamps.len());
    // Frames from after the damaged chunk are there too.
    let clip = mrsmap::io::tum::TumDataset::open(&teddy_clip()).expect("clip");
    assert_eq!(stamps.last(), clip.frames.last().map(|f| f.depth_stamp_ns).as_ref(), "the last frame is read");
}
