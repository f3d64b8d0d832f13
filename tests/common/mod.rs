//! Shared helpers for the integration tests: cameras, shipped data, rendering, maps.
#![allow(dead_code)]

pub mod counting_alloc;
pub mod process;
pub mod scenes;

use mrsmap::frame::RgbdFrame;
use mrsmap::geometry::{CameraModel, PinholeIntrinsics, Pose};
use mrsmap::map::{MapBuilder, MapCapacity, MapParams, SurfelMap};
use mrsmap::synthetic::{Mesh, RenderTarget, render};
use std::path::{Path, PathBuf};

/// The repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The shipped 8-frame TUM teddy clip.
pub fn teddy_clip() -> PathBuf {
    root().join("tests/data/fr3_teddy_8")
}

/// The TUM fr3 camera file.
pub fn fr3_camera_file() -> PathBuf {
    root().join("robot_config/cameras/tum_fr3.toml")
}

/// A VGA pinhole like the TUM fr3 camera.
pub fn vga() -> CameraModel {
    CameraModel {
        width: 640,
        height: 480,
        intrinsics: PinholeIntrinsics { fx: 535.4, fy: 539.2, cx: 320.1, cy: 247.6 },
        distortion: mrsmap::geometry::NO_DISTORTION,
        depth_scale_m: 1.0 / 5000.0,
    }
}

/// Renders `mesh` from `world_from_camera`.
pub fn render_frame(mesh: &Mesh, camera: CameraModel, world_from_camera: &Pose) -> RenderTarget {
    let mut t = RenderTarget::new(camera);
    render(mesh, world_from_camera, &mut t, [0, 0, 0], 0.2);
    t
}

/// Builds a map (odometry parameters) from a rendered frame.
pub fn build_map(target: &RenderTarget) -> SurfelMap {
    build_map_with(target, MapParams::default())
}

/// Builds a map with `params` from a rendered frame.
pub fn build_map_with(target: &RenderTarget, params: MapParams) -> SurfelMap {
    let cam = target.camera;
    let capacity = MapCapacity::for_image((cam.width * cam.height) as usize);
    let mut map = SurfelMap::new(params, capacity).expect("parameters are valid");
    let mut builder = MapBuilder::new(cam.width as usize, cam.height as usize, capacity.surfels);
    let frame = RgbdFrame::new(0, cam, &target.rgb, &target.depth).expect("rendered frame is consistent");
    builder.build(&frame, &mut map).expect("map builds");
    map
}

/// Translation (m) and rotation (deg) between two poses.
pub fn pose_error(a: &Pose, b: &Pose) -> (f64, f64) {
    let d = a.inverse() * b;
    (d.translation.vector.norm(), d.rotation.angle().to_degrees())
}

/// A fresh, empty temporary folder for one test, removed when the test passes and
/// kept (its path printed) when it fails, so a run of the suite leaves nothing behind
/// but the evidence of a failure.
#[must_use = "the folder is removed when this guard is dropped"]
pub struct TempDir(PathBuf);

impl TempDir {
    /// The folder as an owned path (for APIs that take a `PathBuf`).
    pub fn to_path_buf(&self) -> PathBuf {
        self.0.clone()
    }
}

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("kept the failed test's folder {}", self.0.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// A fresh, empty temporary folder for one test (see [`TempDir`]).
pub fn temp_dir(name: &str) -> TempDir {
    let dir = std::env::temp_dir().join(format!("mrsmap-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    TempDir(dir)
}

/// Copies the shipped clip into a temporary folder (to damage it).
pub fn copy_clip(name: &str) -> TempDir {
    let dst = temp_dir(name);
    let src = teddy_clip();
    for sub in ["rgb", "depth"] {
        std::fs::create_dir_all(dst.join(sub)).expect("mkdir");
        for e in std::fs::read_dir(src.join(sub)).expect("read clip") {
            let e = e.expect("entry");
            std::fs::copy(e.path(), dst.join(sub).join(e.file_name())).expect("copy");
        }
    }
    for f in ["associations.txt", "groundtruth.txt"] {
        std::fs::copy(src.join(f), dst.join(f)).expect("copy");
    }
    dst
}

/// An odometry job with default parameters.
pub fn odometry_job(dataset: PathBuf, out: PathBuf, threads: usize) -> mrsmap::app::odometry::OdometryJob {
    mrsmap::app::odometry::OdometryJob {
        dataset,
        camera: fr3_camera_file(),
        out,
        timings: None,
        threads: Some(threads),
        max_frames: None,
        qvga: false,
        params: Default::default(),
        stop: Default::default(),
    }
}

/// The frame rate for a camera driver in a test that expects every frame tracked:
/// `default_hz`, or `MRSMAP_TEST_CAMERA_HZ` where that is set. A tracker slower than its
/// camera drops the frames a newer one replaced, as it should; on a slow computer (an ARM
/// board, an emulator) such tests need a slower camera, e.g. `MRSMAP_TEST_CAMERA_HZ=2`.
pub fn camera_hz(default_hz: u32) -> String {
    match std::env::var("MRSMAP_TEST_CAMERA_HZ") {
        Ok(hz) if hz.parse::<f64>().is_ok_and(|h| h > 0.0 && h.is_finite()) => hz,
        Ok(hz) => panic!("MRSMAP_TEST_CAMERA_HZ={hz}: give frames per second, a positive number"),
        Err(_) => default_hz.to_string(),
    }
}

/// The `mrsmap` binary built for the tests.
pub fn mrsmap_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_mrsmap"))
}

/// A tracker configuration for the shipped teddy model and clip, on services unique to
/// this test (`tag` and the process id), with extra TOML lines for `[tracker]`.
pub fn tracker_config_text(tag: &str, tracker: &str) -> String {
    let id = format!("mrsmap_test_{}_{tag}", std::process::id());
    format!(
        "[camera]\nservice = \"{id}/camera\"\n[poses]\nservice = \"{id}/poses\"\n\
         [detections]\nservice = \"{id}/detections\"\n[tracker]\nthreads = 2\n{tracker}\n\
         [[object]]\nname = \"teddy\"\nmodel = \"{}\"\n\
         camera_from_object = [0.1923, 0.1253, 1.0402, -0.25098, -0.79599, 0.53327, -0.13797]\n\
         search_translation_m = 0.05\nsearch_yaw_deg = 20.0\n",
        root().join("models/teddy.mrsm").display()
    )
}

/// Writes [`tracker_config_text`] to `dir/tracker.toml` and returns its path.
pub fn write_tracker_config(dir: &std::path::Path, tag: &str, tracker: &str) -> PathBuf {
    let path = dir.join("tracker.toml");
    std::fs::write(&path, tracker_config_text(tag, tracker)).expect("write config");
    path
}

/// Kills a child process when dropped (a failing test leaves no stray process).
pub struct ChildGuard(pub std::process::Child);

impl Drop for ChildGuard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `mrsmap camera` looping the shipped clip at `rate` Hz on `service`.
pub fn start_looping_driver(service: &str, rate: &str) -> ChildGuard {
    let camera = std::process::Command::new(mrsmap_bin())
        .args(["camera", "--dataset"])
        .arg(teddy_clip())
        .arg("--camera")
        .arg(fr3_camera_file())
        .args(["--service", service, "--loop", "--rate", rate])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("camera driver starts");
    ChildGuard(camera)
}

/// Recomputes a model file's trailing CRC-32 (IEEE, bit by bit: independent of the
/// crate's table) so that a deliberate change passes the checksum.
pub fn reseal(bytes: &mut [u8]) {
    let n = bytes.len() - 4;
    let mut crc = 0xFFFF_FFFFu32;
    for &b in &bytes[..n] {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    bytes[n..].copy_from_slice(&(!crc).to_le_bytes());
}

/// Runs the `mrsmap` binary with `args` and collects its output.
pub fn mrsmap(args: &[&str]) -> std::process::Output {
    std::process::Command::new(mrsmap_bin()).args(args).output().expect("binary runs")
}

/// A path as the `&str` a command line takes.
pub fn path_str(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}
