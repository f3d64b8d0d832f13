//! `mrsmap synth`: synthetic TUM sequences from a scene file (boxes and a textured OBJ
//! written here, so nothing outside the repository is needed).

mod common;

use common::*;
use mrsmap::app::interrupt::Stop;
use mrsmap::app::synth::{SynthJob, run};
use mrsmap::io::frames::FrameLoader;
use mrsmap::io::scene_file::read_scene;
use mrsmap::io::tum::TumDataset;
use mrsmap::map::{MapBuilder, MapCapacity, MapParams, SurfelMap};
use mrsmap::registration::{RegistrationParams, RegistrationWorkspace, register};
use std::path::{Path, PathBuf};

/// A scene in `dir`: two walls, a table, a box on it and a textured quad (OBJ + PNG),
/// seen along a one-second orbit at 10 Hz (11 frames).
fn write_scene(dir: &Path, camera: &str) -> PathBuf {
    let texture: Vec<u8> = (0..16 * 16).flat_map(|i| [(i * 16 % 256) as u8, (i % 16 * 16) as u8, 128]).collect();
    mrsmap::io::image::write_rgb8(&dir.join("poster.png"), 16, 16, &texture).expect("texture");
    std::fs::write(dir.join("poster.mtl"), "newmtl poster\nmap_Kd poster.png\n").expect("mtl");
    std::fs::write(
        dir.join("poster.obj"),
        "mtllib poster.mtl\nv 0 0 0\nv 0.3 0 0\nv 0.3 0 0.3\nv 0 0 0.3\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n",
    )
    .expect("obj");
    let scene = format!(
        r#"
        camera = "{camera}"
        rate_hz = 10.0
        seed = 5
        [[box]]
        name = "table"
        min = [-0.6, -0.4, 0.0]
        size_m = [1.2, 0.8, 0.75]
        step_m = 0.02
        [[box]]
        name = "wall"
        min = [-1.2, -1.5, 0.0]
        size_m = [0.05, 3.0, 2.0]
        texture_seed = 4
        step_m = 0.04
        [[box]]
        name = "side_wall"
        min = [-1.2, 1.0, 0.0]
        size_m = [2.5, 0.05, 2.0]
        texture_seed = 6
        step_m = 0.04
        [[box]]
        name = "block"
        min = [-0.1, -0.1, 0.75]
        size_m = [0.2, 0.15, 0.12]
        texture_seed = 9
        step_m = 0.02
        [[mesh]]
        name = "poster"
        obj = "poster.obj"
        position = [-0.15, 0.2, 0.75]
        [[sequence]]
        name = "orbit"
        [[sequence.segment]]
        seconds = 1.0
        look_at = [0.0, 0.0, 0.8]
        azimuth_deg = [-20.0, 0.0]
        distance_m = 0.8
        height_m = 0.4
        "#
    );
    let path = dir.join("scene.toml");
    std::fs::write(&path, scene).expect("scene");
    path
}

fn job(scene: PathBuf, out: PathBuf) -> SynthJob {
    SynthJob { scene, out, sequences: Vec::new(), force: false, max_frames: None, stop: Stop::new() }
}

fn camera_file(name: &str) -> String {
    root().join("robot_config/cameras").join(name).display().to_string()
}

/// Every file under `dir`, relative, with its bytes.
fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    for sub in ["", "rgb", "depth"] {
        for e in std::fs::read_dir(dir.join(sub)).expect("folder") {
            let path = e.expect("entry").path();
            if path.is_file() {
                out.push((path.strip_prefix(dir).expect("inside").to_path_buf(), std::fs::read(&path).expect("read")));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn a_scene_becomes_a_tum_sequence_with_its_exact_ground_truth() {
    let dir = temp_dir("synth-sequence");
    let scene = write_scene(&dir, &camera_file("tum_fr3.toml"));
    let summary = run(&job(scene.clone(), dir.join("out"))).expect("renders");
    assert_eq!(summary.sequences.len(), 1);
    assert_eq!(summary.sequences[0].frames, 11);
    assert!(summary.interrupted.is_none());
    let folder = dir.join("out/orbit");
    assert!(!dir.join("out/orbit.partial").exists(), "the partial folder is renamed");
    let dataset = TumDataset::open(&folder).expect("a TUM dataset");
    assert_eq!(dataset.frames.len(), 11);
    // Stamps in whole microseconds, 0.1 s apart; the ground truth is the scene's path.
    let path = &read_scene(&scene).expect("scene").sequences[0].path;
    let gt = dataset.groundtruth.as_ref().expect("groundtruth.txt");
    for (k, f) in dataset.frames.iter().enumerate() {
        assert_eq!(f.depth_stamp_ns % 1000, 0);
        assert_eq!(f.depth_stamp_ns - dataset.frames[0].depth_stamp_ns, k as u64 * 100_000_000);
        let (t, deg) =
            pose_error(&gt.at_stamp_ns(f.depth_stamp_ns).expect("pose"), &path.world_from_camera(k as f64 / 10.0));
        // (Stamps as f64 seconds resolve ~0.2 µs at Unix times: the lookup interpolates.)
        assert!(t < 1e-6 && deg < 1e-4, "frame {k}: {t} m, {deg}°");
    }
    // The sensor: most of the view measured, but not all (projector shadows, edges).
    let mut loader = FrameLoader::new(mrsmap::io::camera_file::read_camera(&fr3_camera_file()).expect("camera"), false);
    let frame = loader.load(&dataset.frames[0]).expect("frame");
    let valid = frame.depth.iter().filter(|&&d| d > 0).count() as f64 / frame.depth.len() as f64;
    assert!(valid > 0.6 && valid < 0.999, "share of pixels with depth: {valid}");
    // The textured quad's colours are in the image (not only the boxes' and the background's).
    assert!(frame.rgb.chunks_exact(3).any(|p| p[2] > 110 && p[2] < 146 && p[0] > 200), "texture seen");
}

/// Registers frame 1 of the orbit to frame 0, rendered with `sensor` (a `[sensor]` table's
/// lines, empty: the default Kinect): the error against the ground truth (m, degrees) and
/// the length of the true step (m).
fn registration_error(name: &str, sensor: &str) -> (f64, f64, f64) {
    let dir = temp_dir(name);
    let scene = write_scene(&dir, &camera_file("tum_fr3.toml"));
    let text =
        std::fs::read_to_string(&scene).expect("scene").replace("seed = 5", &format!("seed = 5\n[sensor]\n{sensor}"));
    std::fs::write(&scene, text).expect("scene");
    run(&SynthJob { max_frames: Some(2), ..job(scene, dir.join("out")) }).expect("renders");
    let dataset = TumDataset::open(&dir.join("out/orbit")).expect("dataset");
    let gt = dataset.groundtruth.clone().expect("ground truth");
    let camera = mrsmap::io::camera_file::read_camera(&fr3_camera_file()).expect("camera");
    let capacity = MapCapacity::for_image(640 * 480);
    let mut builder = MapBuilder::new(640, 480, capacity.surfels);
    let mut loader = FrameLoader::new(camera, false);
    let mut maps = Vec::new();
    for entry in &dataset.frames[..2] {
        let mut map = SurfelMap::new(MapParams::default(), capacity).expect("params");
        builder.build(&loader.load(entry).expect("frame"), &mut map).expect("map");
        maps.push(map);
    }
    let world_from = |i: usize| gt.at_stamp_ns(dataset.frames[i].depth_stamp_ns).expect("pose");
    let truth = world_from(0).inverse() * world_from(1);
    let mut ws = RegistrationWorkspace::new(capacity.nodes);
    let r = register(&maps[0], &maps[1], &mrsmap::geometry::Pose::identity(), &RegistrationParams::default(), &mut ws)
        .expect("registers");
    let (t, deg) = pose_error(&r.model_from_scene, &truth);
    (t, deg, pose_error(&truth, &mrsmap::geometry::Pose::identity()).0)
}

#[test]
fn registration_on_rendered_sensor_data_finds_the_true_motion() {
    // An exact sensor: 0.9 mm, 0.07° measured; the Kinect's depth noise and quantisation
    // (2.3 mm steps at this range): 3.9 mm, 0.3° (noise alone 3.0 mm, steps alone 2.2).
    let exact = "disparity_noise_px = 0.0\ndisparity_step_px = 0.0\nprojector_shadows = false\nedge_dropout = 0.0\ncolor_noise = 0.0";
    let (t, deg, moved) = registration_error("synth-register-exact", exact);
    assert!(moved > 0.02, "the camera moved {moved} m");
    assert!(t < 0.002 && deg < 0.15, "exact: {:.1} mm, {deg:.2}° for a {:.0} mm step", t * 1e3, moved * 1e3);
    let (t_kinect, deg_kinect, _) = registration_error("synth-register-kinect", "");
    assert!(
        t_kinect < 0.006 && deg_kinect < 0.6 && t_kinect > t,
        "Kinect: {:.1} mm, {deg_kinect:.2}° (exact {:.1} mm) for a {:.0} mm step",
        t_kinect * 1e3,
        t * 1e3,
        moved * 1e3
    );
}

#[test]
fn the_same_scene_renders_the_same_bytes_and_outputs_are_not_replaced_unasked() {
    let dir = temp_dir("synth-repeat");
    let scene = write_scene(&dir, &camera_file("tum_fr3.toml"));
    run(&SynthJob { max_frames: Some(4), ..job(scene.clone(), dir.join("a")) }).expect("renders");
    run(&SynthJob { max_frames: Some(4), ..job(scene.clone(), dir.join("b")) }).expect("renders");
    assert_eq!(files(&dir.join("a/orbit")), files(&dir.join("b/orbit")));
    let again = run(&job(scene.clone(), dir.join("a"))).expect_err("exists");
    assert!(again.to_string().contains("exists; pass --force"), "{again}");
    let forced = run(&SynthJob { force: true, ..job(scene, dir.join("a")) }).expect("replaces");
    assert_eq!(forced.sequences[0].frames, 11);
}

#[test]
fn an_interrupted_render_keeps_a_complete_shorter_sequence() {
    let dir = temp_dir("synth-interrupt");
    let scene = write_scene(&dir, &camera_file("tum_fr3.toml"));
    // The stop is asked for before the second batch of frames.
    let summary = run(&SynthJob { stop: Stop::after_frames(1), ..job(scene, dir.join("out")) }).expect("renders");
    let interrupted = summary.interrupted.expect("interrupted");
    let frames = summary.sequences[0].frames;
    assert!(frames > 0 && frames < 11 && interrupted.after == frames, "{frames} frames, {interrupted}");
    let dataset = TumDataset::open(&dir.join("out/orbit")).expect("a complete dataset");
    assert_eq!(dataset.frames.len(), frames);
    let gt = dataset.groundtruth.expect("ground truth");
    let last = dataset.frames[frames - 1].depth_stamp_ns;
    assert!(
        gt.at_stamp_ns(last).is_some() && gt.at_stamp_ns(last + 20_000_000).is_none(),
        "ground truth to the last frame"
    );
    let source = std::fs::read_to_string(dir.join("out/orbit/SOURCE.txt")).expect("SOURCE.txt");
    assert!(source.contains(&format!("interrupted after {frames} of 11 frames")), "{source}");
}

#[test]
fn bad_scenes_are_refused_with_what_is_wrong() {
    let dir = temp_dir("synth-bad");
    // A camera with lens distortion cannot be rendered by a pinhole.
    let distorted = std::fs::read_to_string(fr3_camera_file())
        .expect("camera")
        .replace("distortion = [0.0, 0.0, 0.0, 0.0, 0.0]", "distortion = [0.2624, -0.9531, -0.0054, 0.0026, 1.1633]");
    assert!(distorted.contains("0.2624"), "the camera file has a distortion line to change");
    std::fs::write(dir.join("lens.toml"), distorted).expect("camera");
    let scene = write_scene(&dir, "lens.toml");
    let e = format!("{:#}", run(&job(scene, dir.join("out"))).expect_err("distorted"));
    assert!(e.contains("lens.toml") && e.contains("distortion"), "{e}");
    // A missing mesh file names the mesh and the file.
    let scene = write_scene(&dir, &camera_file("tum_fr3.toml"));
    std::fs::remove_file(dir.join("poster.obj")).expect("remove");
    let e = format!("{:#}", run(&job(scene.clone(), dir.join("out"))).expect_err("no mesh"));
    assert!(e.contains("\"poster\"") && e.contains("poster.obj"), "{e}");
    // An unknown sequence lists the known ones.
    let e = run(&SynthJob { sequences: vec!["orbitt".into()], ..job(scene, dir.join("out")) }).expect_err("unknown");
    assert!(e.to_string().contains("orbitt") && e.to_string().contains("orbit)"), "{e}");
    // A scene file that does not parse names itself.
    let broken = dir.join("broken.toml");
    std::fs::write(&broken, "camera = 3").expect("write");
    let e = run(&job(broken, dir.join("out"))).expect_err("broken");
    assert!(e.to_string().contains("broken.toml"), "{e}");
}
