//! Bad input gets a clear error naming what was wrong, or a registration marked failed;
//! never a panic, never a silently wrong trajectory.

mod common;

use common::*;
use mrsmap::app::odometry::run;
use mrsmap::frame::{FrameError, RgbdFrame};
use mrsmap::geometry::Pose;
use mrsmap::geometry::se3::left_increment;
use mrsmap::io::camera_file::{CameraFileError, read_camera};
use mrsmap::io::frames::{FrameLoader, LoadError};
use mrsmap::io::image::{ImageError, write_depth16, write_rgb8};
use mrsmap::io::tum::TumDataset;
use mrsmap::synthetic::room;
use nalgebra::Vector6;
use std::path::Path;

#[test]
fn camera_files_with_bad_values_name_the_parameter() {
    let dir = temp_dir("camera");
    let good = std::fs::read_to_string(fr3_camera_file()).expect("camera");
    for (from, to, name) in
        [("fx = 535.4", "fx = nan", "fx"), ("fy = 539.2", "fy = 0.0", "fy"), ("fx = 535.4", "fx = -5.0", "fx")]
    {
        let path = dir.join(format!("{name}.toml"));
        std::fs::write(&path, good.replace(from, to)).expect("write");
        let err = read_camera(&path).expect_err("must be rejected");
        let msg = err.to_string();
        assert!(
            matches!(err, CameraFileError::Invalid { .. })
                && msg.contains(name)
                && msg.contains(&*path.to_string_lossy()),
            "{msg}"
        );
    }
    let missing = dir.join("missing.toml");
    std::fs::write(&missing, good.replace("cy = 247.6\n", "")).expect("write");
    assert!(read_camera(&missing).expect_err("incomplete").to_string().contains("cy"));
    let err = read_camera(&dir.join("does-not-exist.toml")).expect_err("no file");
    assert!(err.to_string().contains("does-not-exist.toml"));
}

#[test]
fn unreadable_images_name_the_file() {
    let dir = copy_clip("images");
    let camera = read_camera(&fr3_camera_file()).expect("camera");
    let frames = TumDataset::open(&dir).expect("clip").frames;
    let mut loader = FrameLoader::new(camera, false);

    // Missing file.
    std::fs::remove_file(&frames[0].rgb_path).expect("rm");
    let err = loader.load(&frames[0]).expect_err("missing");
    assert!(matches!(err, LoadError::Image(ImageError::Io { .. })) && err.to_string().contains("rgb/"), "{err}");

    // Truncated PNG.
    let bytes = std::fs::read(&frames[1].depth_path).expect("read");
    std::fs::write(&frames[1].depth_path, &bytes[..bytes.len() / 3]).expect("truncate");
    let err = loader.load(&frames[1]).expect_err("truncated");
    assert!(matches!(err, LoadError::Image(ImageError::Decode { .. })) && err.to_string().contains("depth/"), "{err}");

    // Wrong size.
    write_depth16(&frames[2].depth_path, 320, 240, &vec![5000u16; 320 * 240]).expect("write");
    let err = loader.load(&frames[2]).expect_err("wrong size");
    assert!(matches!(err, LoadError::Image(ImageError::Size { width: 320, height: 240, .. })), "{err}");

    // Wrong bit depth: an 8-bit image where 16-bit depth is expected.
    write_rgb8(&frames[3].depth_path, 640, 480, &vec![0u8; 640 * 480 * 3]).expect("write");
    let err = loader.load(&frames[3]).expect_err("8-bit depth");
    assert!(matches!(err, LoadError::Image(ImageError::Format { .. })) && err.to_string().contains("16-bit"), "{err}");

    // All-zero depth.
    write_depth16(&frames[4].depth_path, 640, 480, &vec![0u16; 640 * 480]).expect("write");
    let err = loader.load(&frames[4]).expect_err("no depth");
    assert!(matches!(err, LoadError::NoValidDepth { .. }) && err.to_string().contains("no valid pixel"), "{err}");
}

#[test]
fn frame_buffers_must_match_the_camera() {
    let cam = vga();
    let err = RgbdFrame::new(0, cam, &[0u8; 10], &vec![0u16; 640 * 480]).expect_err("short rgb");
    assert!(matches!(err, FrameError::BufferSize { what: "rgb", .. }), "{err}");
    let mut bad = cam;
    bad.intrinsics.fx = f64::NAN;
    let err = RgbdFrame::new(0, bad, &vec![0u8; 640 * 480 * 3], &vec![0u16; 640 * 480]).expect_err("nan fx");
    assert!(err.to_string().contains("fx"), "{err}");
}

#[test]
fn odometry_skips_damaged_frames_and_says_so() {
    let dir = copy_clip("odometry-damaged");
    let frames = TumDataset::open(&dir).expect("clip").frames;
    let bytes = std::fs::read(&frames[3].rgb_path).expect("read");
    std::fs::write(&frames[3].rgb_path, &bytes[..100]).expect("truncate");
    write_depth16(&frames[5].depth_path, 640, 480, &vec![0u16; 640 * 480]).expect("write");
    let out = dir.join("traj.txt");
    let s = run(&odometry_job(dir.to_path_buf(), out.clone(), 2)).expect("the other frames are processed");
    assert_eq!((s.frames, s.skipped), (6, 2));
    let text = std::fs::read_to_string(&out).expect("trajectory");
    assert_eq!(text.lines().filter(|l| !l.starts_with('#')).count(), 6);
    assert!(text.contains("# skipped") && text.contains("no valid pixel"), "{text}");
    assert!(s.rpe.expect("ground truth").max < 10e-3);
}

#[test]
fn odometry_with_the_wrong_camera_fails_at_the_first_frame() {
    let dir = temp_dir("wrong-camera");
    let camera = dir.join("qvga.toml");
    let text = std::fs::read_to_string(fr3_camera_file()).expect("camera");
    std::fs::write(&camera, text.replace("width = 640", "width = 320").replace("height = 480", "height = 240"))
        .expect("write");
    let mut job = odometry_job(teddy_clip(), dir.join("traj.txt"), 2);
    job.camera = camera;
    let err = run(&job).expect_err("sizes disagree");
    assert!(err.to_string().contains("640x480") && err.to_string().contains("camera file"), "{err}");
    assert!(!dir.join("traj.txt").exists(), "no trajectory from a misconfigured run");
}

#[test]
fn missing_dataset_is_a_clear_error() {
    let dir = temp_dir("missing");
    let job = odometry_job("/nonexistent/dataset".into(), dir.join("t.txt"), 1);
    let err = run(&job).expect_err("no dataset");
    assert!(format!("{err:#}").contains("/nonexistent/dataset"), "{err:#}");
}

/// Writes a rendered sequence as a TUM folder with rgb.txt and depth.txt (no
/// associations.txt, so the reader associates the lists itself).
fn write_rendered_dataset(dir: &Path, poses: &[Pose]) {
    use mrsmap::synthetic::scene::{ColorField, add_quad};
    use nalgebra::Vector3;
    // The tabletop in front of the camera, and an unrelated wall behind it.
    let mut mesh = room(5);
    let field = ColorField::new(&mut mrsmap::synthetic::Pcg32::new(99), 12);
    add_quad(
        &mut mesh,
        Vector3::new(-1.5, -1.0, -1.5),
        Vector3::new(3.0, 0.0, 0.0),
        Vector3::new(0.0, 2.0, 0.0),
        0.01,
        &field,
    );
    std::fs::create_dir_all(dir.join("rgb")).expect("mkdir");
    std::fs::create_dir_all(dir.join("depth")).expect("mkdir");
    let (mut rgb_list, mut depth_list) = (String::from("# color images\n"), String::from("# depth maps\n"));
    for (i, pose) in poses.iter().enumerate() {
        let t = render_frame(&mesh, vga(), pose);
        let stamp = format!("1000.{:06}", 33_000 * i);
        write_rgb8(&dir.join(format!("rgb/{stamp}.png")), 640, 480, &t.rgb).expect("png");
        write_depth16(&dir.join(format!("depth/{stamp}.png")), 640, 480, &t.depth).expect("png");
        rgb_list.push_str(&format!("{stamp} rgb/{stamp}.png\n"));
        depth_list.push_str(&format!("{stamp} depth/{stamp}.png\n"));
    }
    std::fs::write(dir.join("rgb.txt"), rgb_list).expect("write");
    std::fs::write(dir.join("depth.txt"), depth_list).expect("write");
}

#[test]
fn a_frame_without_overlap_is_marked_failed_and_the_pose_held() {
    let dir = temp_dir("no-overlap");
    let step = |k: f64| left_increment(&Vector6::new(0.01 * k, 0.0, 0.0, 0.0, 0.0, 0.0));
    // Frame 2 turns around to the wall behind: nothing in common with frame 1.
    let away = step(2.0) * left_increment(&Vector6::new(0.0, 0.0, 0.0, 0.0, std::f64::consts::PI, 0.0));
    write_rendered_dataset(&dir, &[step(0.0), step(1.0), away, step(3.0)]);
    let out = dir.join("traj.txt");
    let mut job = odometry_job(dir.to_path_buf(), out.clone(), 2);
    job.camera = dir.join("cam.toml");
    std::fs::write(
        &job.camera,
        "width = 640\nheight = 480\nfx = 535.4\nfy = 539.2\ncx = 320.1\ncy = 247.6\ndepth_scale_m = 0.0002\n",
    )
    .expect("camera");
    let s = run(&job).expect("runs");
    assert_eq!(s.frames, 4);
    assert!(s.failed >= 1, "the turned-away frame must fail: {s:?}");
    let text = std::fs::read_to_string(&out).expect("trajectory");
    assert!(text.contains("registration failed"), "{text}");
}

#[test]
fn eval_without_common_stamps_is_an_error() {
    use mrsmap::eval::associate;
    use mrsmap::io::tum::Trajectory;
    let a = Trajectory { stamps: vec![1.0, 2.0], poses: vec![Pose::identity(); 2] };
    let b = Trajectory { stamps: vec![10.0, 11.0], poses: vec![Pose::identity(); 2] };
    let err = associate(&a, &b, 0.02).expect_err("disjoint");
    assert!(err.to_string().contains("no matching timestamps"), "{err}");
}
