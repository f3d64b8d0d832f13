//! The text files a user writes or a tool produced: camera files, tracker
//! configurations, object descriptions (TOML), TUM lists and trajectories. Each parses
//! or gives a typed error, never panics; `eval` on two trajectories that parse gives
//! errors or finite numbers.

#![no_main]

use libfuzzer_sys::arbitrary::{self, Arbitrary};
use libfuzzer_sys::fuzz_target;
use mrsmap::eval::{associate, ate_translation, rpe_translation};
use mrsmap::io::camera_file::parse_camera;
use mrsmap::io::object_file::parse_object;
use mrsmap::io::tracker_config::parse_tracker_config;
use mrsmap::io::tum::{Trajectory, read_file_list};
use std::path::{Path, PathBuf};

#[derive(Debug, Arbitrary)]
struct Texts {
    camera: String,
    config: String,
    object: String,
    reference: String,
    estimate: String,
    delta: u8,
}

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("mrsmap-fuzz-{}-{name}", std::process::id()))
}

/// Reads `text` the way the tools read a file.
fn through_file<T>(name: &str, text: &str, read: impl Fn(&Path) -> T) -> Option<T> {
    let path = temp(name);
    std::fs::write(&path, text).ok()?;
    Some(read(&path))
}

/// Coordinates of a size a trajectory can have (km, not 1e300).
fn plausible(t: &Trajectory) -> bool {
    t.poses.iter().all(|p| p.translation.vector.amax() < 1e4) && t.stamps.iter().all(|s| s.abs() < 1e10)
}

fuzz_target!(|texts: Texts| {
    let origin = Path::new("fuzz.toml");
    if let Ok(camera) = parse_camera(&texts.camera, origin) {
        assert!(camera.validate().is_ok(), "accepted an invalid camera: {camera:?}");
    }
    let _ = parse_tracker_config(&texts.config, origin);
    let _ = parse_object(&texts.object, origin);
    let _ = through_file("list.txt", &texts.reference, read_file_list);
    let (Some(Ok(reference)), Some(Ok(estimate))) = (
        through_file("reference.txt", &texts.reference, Trajectory::read),
        through_file("estimate.txt", &texts.estimate, Trajectory::read),
    ) else {
        return;
    };
    let _ = reference.interpolate(estimate.stamps[0], 0.1);
    let Ok((r, e)) = associate(&reference, &estimate, 0.02) else { return };
    let finite = plausible(&reference) && plausible(&estimate);
    for errors in [rpe_translation(&r, &e, texts.delta as usize), ate_translation(&r, &e)].into_iter().flatten() {
        if finite {
            assert!(errors.iter().all(|x| x.is_finite()), "non-finite errors {errors:?}");
        }
    }
});
