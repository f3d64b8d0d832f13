//! The tracker's per-frame step on what a camera driver may send: real frames of the
//! teddy (tests/data/fr3_teddy_8, QVGA) with any header (intrinsics, distortion, depth
//! scale) and patches of any depth and colour, several frames in a row from the ground-
//! truth pose. Every frame ends in an estimate, never a panic; a frame the wire check
//! rejects gives status "invalid frame"; every published pose, covariance and quality
//! is finite.

#![no_main]

use libfuzzer_sys::arbitrary::{self, Arbitrary};
use libfuzzer_sys::fuzz_target;
use mrsmap::geometry::Pose;
use mrsmap::io::camera_file::read_camera;
use mrsmap::io::frames::FrameLoader;
use mrsmap::io::tum::TumDataset;
use mrsmap::io::wire::{FrameHeader, RgbdFrameQvga, WireFrame};
use mrsmap::tracking::{ObjectModel, PoseEstimate, SearchRegion, Tracker, TrackerParams, TrackingStatus};
use std::path::Path;
use std::sync::OnceLock;

const WIDTH: usize = 320;
const HEIGHT: usize = 240;

#[derive(Debug, Arbitrary)]
struct Intrinsics {
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    distortion: [f64; 8],
    depth_scale_m: f64,
}

#[derive(Debug, Arbitrary)]
struct Patch {
    u: u16,
    v: u16,
    width: u8,
    height: u8,
    depth: u16,
    rgb: [u8; 3],
}

#[derive(Debug, Arbitrary)]
struct FuzzFrame {
    base: u8,
    /// `None`: the dataset's camera.
    intrinsics: Option<Intrinsics>,
    layout_version: Option<u32>,
    stamp_ns: u64,
    patches: Vec<Patch>,
}

/// The teddy model, the shipped frames (decoded, QVGA) and the first frame's pose.
struct Fixture {
    model: ObjectModel,
    header: FrameHeader,
    frames: Vec<(Vec<u8>, Vec<u16>)>,
}

fn fixture() -> &'static Fixture {
    static FIXTURE: OnceLock<Fixture> = OnceLock::new();
    FIXTURE.get_or_init(|| {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let model = mrsmap::model::load(&root.join("models/teddy.mrsm")).expect("the teddy model loads");
        let world_from_model = model.world_from_model();
        let dataset = TumDataset::open(&root.join("tests/data/fr3_teddy_8")).expect("the shipped frames");
        let camera = read_camera(&root.join("robot_config/cameras/tum_fr3.toml")).expect("the camera file");
        let gt = dataset.groundtruth.as_ref().expect("ground truth");
        let first = &dataset.frames[0];
        let world_from_camera =
            gt.interpolate(first.depth_stamp_ns as f64 * 1e-9, 0.1).expect("ground truth covers it");
        let object_from_camera: Pose = world_from_model.inverse() * world_from_camera;
        let mut loader = FrameLoader::new(camera, true);
        let frames = dataset
            .frames
            .iter()
            .map(|f| {
                let frame = loader.load(f).expect("a shipped frame loads");
                (frame.rgb.to_vec(), frame.depth.to_vec())
            })
            .collect();
        let header = FrameHeader::for_camera(&loader.camera(), 0, 0);
        let model = ObjectModel {
            name: "teddy".into(),
            extent: model.extent().expect("the teddy's extent"),
            map: model.map,
            initial_camera_from_object: object_from_camera.inverse(),
            search: SearchRegion { translation_m: 0.05, yaw_rad: 0.35 },
            color_term: None,
        };
        Fixture { model, header, frames }
    })
}

/// The wire message a driver would send for `f`.
fn message(fixture: &Fixture, f: &FuzzFrame) -> Box<RgbdFrameQvga> {
    let (rgb, depth) = &fixture.frames[f.base as usize % fixture.frames.len()];
    let mut header = fixture.header;
    header.capture_stamp_ns = f.stamp_ns;
    if let Some(version) = f.layout_version {
        header.layout_version = version;
    }
    if let Some(k) = &f.intrinsics {
        (header.fx, header.fy, header.cx, header.cy) = (k.fx, k.fy, k.cx, k.cy);
        header.distortion = k.distortion;
        header.depth_scale_m = k.depth_scale_m;
    }
    let mut m = Box::new(RgbdFrameQvga { header, rgb: [0; WIDTH * HEIGHT * 3], depth: [0; WIDTH * HEIGHT] });
    m.rgb.copy_from_slice(rgb);
    m.depth.copy_from_slice(depth);
    for p in f.patches.iter().take(16) {
        let (u0, v0) = (p.u as usize % WIDTH, p.v as usize % HEIGHT);
        for v in v0..(v0 + p.height as usize).min(HEIGHT) {
            for u in u0..(u0 + p.width as usize).min(WIDTH) {
                m.depth[v * WIDTH + u] = p.depth;
                m.rgb[3 * (v * WIDTH + u)..3 * (v * WIDTH + u) + 3].copy_from_slice(&p.rgb);
            }
        }
    }
    m
}

fn check(e: &PoseEstimate) {
    let t = e.camera_from_object.translation.vector;
    let q = e.camera_from_object.rotation.quaternion().coords;
    assert!(t.iter().chain(q.iter()).all(|x| x.is_finite()), "non-finite pose {e:?}");
    assert!(e.covariance_ros.iter().all(|x| x.is_finite()), "non-finite covariance {e:?}");
    assert!(e.quality.is_finite(), "non-finite quality {e:?}");
}

fuzz_target!(|frames: Vec<FuzzFrame>| {
    let fixture = fixture();
    let mut tracker = Tracker::new(TrackerParams::default(), WIDTH, HEIGHT, vec![fixture.model.clone()])
        .expect("a tracker for the teddy");
    let mut out = [tracker.invalid_frame(0, 0)];
    for f in frames.iter().take(4) {
        let m = message(fixture, f);
        match m.frame() {
            Ok(frame) => tracker.step(&frame, &mut out),
            Err(_) => {
                out[0] = tracker.invalid_frame(0, f.stamp_ns);
                assert_eq!(out[0].status, TrackingStatus::InvalidFrame);
            }
        }
        check(&out[0]);
    }
});
