//! The `mrsmap map` and `mrsmap model` commands end to end on the shipped clip.

mod common;

use common::*;
use mrsmap::io::tum::TumDataset;

#[test]
fn map_then_model_info_and_render() {
    let dir = temp_dir("cli-map");
    let (model, traj, png) = (dir.join("teddy.mrsm"), dir.join("slam.txt"), dir.join("teddy.png"));
    let object = root().join("robot_config/objects/teddy.toml");
    let (clip, camera) = (teddy_clip(), fr3_camera_file());
    let args = [
        "map",
        "--dataset",
        path_str(&clip),
        "--camera",
        path_str(&camera),
        "--object",
        path_str(&object),
        "--out",
        path_str(&model),
        "--trajectory",
        path_str(&traj),
    ];
    let out = mrsmap(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    for word in ["8 frames", "key views", "loop closures", "graph step", "ATE", "model 'teddy' (object frame)"] {
        assert!(text.contains(word), "missing {word:?} in\n{text}");
    }
    assert_eq!(std::fs::read_to_string(&traj).expect("trajectory").lines().filter(|l| !l.starts_with('#')).count(), 8);
    // The clip sees little of the box top: the support plane's fit settles on a surface
    // ~20° off the footprint's plane, and the tool says so.
    assert!(text.contains("warning: the support plane was fitted"), "{text}");
    // The model is not overwritten by accident.
    let again = mrsmap(&args);
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("--force"), "{}", String::from_utf8_lossy(&again.stderr));
    let info = mrsmap(&["model", "info", path_str(&model)]);
    assert!(info.status.success(), "{}", String::from_utf8_lossy(&info.stderr));
    let text = String::from_utf8_lossy(&info.stdout);
    for word in ["model 'teddy'", "frame            object", "prism", "root statistics", "usable surfels"] {
        assert!(text.contains(word), "missing {word:?} in\n{text}");
    }
    let render =
        mrsmap(&["model", "render", path_str(&model), "--out", path_str(&png), "--width", "320", "--height", "240"]);
    assert!(render.status.success(), "{}", String::from_utf8_lossy(&render.stderr));
    let mut reader = mrsmap::io::image::PngReader::default();
    let mut rgb = Vec::new();
    reader.read_rgb8(&png, (320, 240), &mut rgb).expect("a 320x240 RGB picture");
    let background = rgb.chunks_exact(3).filter(|p| p == &[32, 34, 38]).count();
    assert!(background < 320 * 240 * 95 / 100, "the picture shows the model ({background} background pixels)");
    // A damaged model: a clear error naming the file.
    let bytes = std::fs::read(&model).expect("model");
    let cut = dir.join("cut.mrsm");
    std::fs::write(&cut, &bytes[..bytes.len() / 3]).expect("write");
    let info = mrsmap(&["model", "info", path_str(&cut)]);
    assert!(!info.status.success());
    let err = String::from_utf8_lossy(&info.stderr);
    assert!(err.contains("cut.mrsm") && err.contains("truncated"), "{err}");
}

/// The map tool puts its world frame on the ground truth by aligning whole poses: even
/// three frames (camera centres 2 mm apart, on a near-straight line that leaves a
/// positions-only alignment's rotation free) give a world frame whose camera
/// orientations agree with the motion capture, and an object model on the fitted
/// support plane.
#[test]
fn a_short_map_run_lands_in_the_ground_truth_frame() {
    let dir = temp_dir("cli-map-short");
    let (model, traj) = (dir.join("teddy.mrsm"), dir.join("slam.txt"));
    let object = root().join("robot_config/objects/teddy.toml");
    let (clip, camera) = (teddy_clip(), fr3_camera_file());
    let out = mrsmap(&[
        "map",
        "--dataset",
        path_str(&clip),
        "--camera",
        path_str(&camera),
        "--object",
        path_str(&object),
        "--max-frames",
        "3",
        "--out",
        path_str(&model),
        "--trajectory",
        path_str(&traj),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let estimate = mrsmap::io::tum::Trajectory::read(&traj).expect("trajectory");
    let truth = TumDataset::open(&clip).expect("clip").groundtruth.expect("ground truth");
    assert_eq!(estimate.poses.len(), 3);
    for (stamp, pose) in estimate.stamps.iter().zip(&estimate.poses) {
        let (gt, gap) = truth.nearest(*stamp).expect("ground truth near the frame");
        assert!(gap < 0.02);
        let degrees = pose.rotation.angle_to(&gt.rotation).to_degrees();
        assert!(degrees < 0.5, "orientation {degrees:.2}° off the ground truth at {stamp}");
        assert!((pose.translation.vector - gt.translation.vector).norm() < 0.01);
    }
    assert!(model.exists());
}

#[test]
fn map_refuses_to_run_with_nothing_to_write_and_reports_an_empty_volume() {
    let dir = temp_dir("cli-map-empty");
    let (clip, camera) = (teddy_clip(), fr3_camera_file());
    let out = mrsmap(&["map", "--dataset", path_str(&clip), "--camera", path_str(&camera)]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("nothing to write"));
    let object = dir.join("far.toml");
    std::fs::write(&object, "name = \"far\"\n[volume]\ncenter = [40.0, 0.0, 0.0]\nhalf_extents_m = [0.2, 0.2, 0.2]\n")
        .expect("write");
    let (model, traj) = (dir.join("far.mrsm"), dir.join("slam.txt"));
    let out = mrsmap(&[
        "map",
        "--dataset",
        path_str(&clip),
        "--camera",
        path_str(&camera),
        "--object",
        path_str(&object),
        "--out",
        path_str(&model),
        "--trajectory",
        path_str(&traj),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("volume of interest") && err.contains("trajectory was written"), "{err}");
    assert!(traj.exists(), "the trajectory is kept");
    assert!(!model.exists(), "no half-made model");
}
