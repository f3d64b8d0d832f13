//! The model file format: round trip, damaged files, and a checked-in golden model.
//!
//! Regenerate the golden model after a deliberate format change (and bump
//! `FORMAT_VERSION`): `MRSMAP_REGENERATE_GOLDEN=1 cargo test --release --test model_file`.

mod common;

use common::*;
use mrsmap::geometry::{CameraModel, PinholeIntrinsics};
use mrsmap::model::{FORMAT_VERSION, MAGIC, Model, ModelError, ModelHeader, ModelSource, RootStats, decode, encode};
use mrsmap::synthetic::room;
use std::path::Path;

/// A small camera: a model of a few hundred surfels.
fn tiny_camera() -> CameraModel {
    CameraModel {
        width: 80,
        height: 60,
        intrinsics: PinholeIntrinsics { fx: 66.9, fy: 67.4, cx: 40.0, cy: 30.0 },
        distortion: mrsmap::geometry::NO_DISTORTION,
        depth_scale_m: 1.0 / 5000.0,
    }
}

/// The golden model: one rendered view of the synthetic room.
fn golden_model() -> Model {
    let target = render_frame(&room(9), tiny_camera(), &mrsmap::geometry::Pose::identity());
    let map = build_map(&target);
    let header = ModelHeader {
        name: "golden".into(),
        frame: "world".into(),
        map_params: map.params().into(),
        volume: None,
        world_from_model: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        source: ModelSource {
            dataset: "synthetic room, seed 9, 80x60".into(),
            camera: "tiny".into(),
            frames: 1,
            first_stamp_ns: 0,
            last_stamp_ns: 0,
            key_views: 1,
            created_by: "tests/model_file.rs".into(),
        },
        root: RootStats::of(&map),
        nodes: map.nodes().len() as u32,
        surfels: map.surfels().len() as u32,
    };
    Model { header, map }
}

fn golden_path() -> std::path::PathBuf {
    root().join("tests/data/golden.mrsm")
}

#[test]
fn round_trip_restores_the_map_exactly() {
    let model = golden_model();
    let bytes = encode(&model);
    let back = decode(&bytes, Path::new("memory")).expect("decodes");
    assert_eq!(back.header, model.header);
    assert_eq!(back.map.parts(), model.map.parts());
    assert_eq!(back.map.surfels(), model.map.surfels(), "evaluated surfels are recomputed identically");
    assert_eq!(back.map.normals(), model.map.normals());
    assert_eq!(back.map.descriptors(), model.map.descriptors());
    assert_eq!(encode(&back), bytes, "re-encoding is byte-identical");
}

/// A map built without its colour statistics (odometry's and the tracker's setting)
/// is refused as a model, and nothing is written.
#[test]
fn a_map_without_colour_statistics_is_not_saved() {
    let target = render_frame(&room(9), tiny_camera(), &mrsmap::geometry::Pose::identity());
    let map = build_map_with(&target, mrsmap::map::MapParams { color_scatter: false, ..Default::default() });
    let model = Model { map, ..golden_model() };
    let dir = temp_dir("no-colour");
    let path = dir.join("m.mrsm");
    let err = mrsmap::model::save(&path, &model).expect_err("refused");
    assert!(matches!(err, ModelError::NoColorScatter { .. }), "{err}");
    assert!(err.to_string().contains("colour statistics"), "{err}");
    assert!(!path.exists() && !path.with_extension("mrsm.partial").exists());
}

#[test]
fn the_golden_model_still_reads_and_pins_the_format() {
    let path = golden_path();
    if std::env::var_os("MRSMAP_REGENERATE_GOLDEN").is_some() {
        mrsmap::model::save(&path, &golden_model()).expect("write golden");
    }
    let bytes = std::fs::read(&path).expect("tests/data/golden.mrsm is checked in");
    assert_eq!(bytes[..8], MAGIC);
    assert_eq!(
        u16::from_le_bytes([bytes[8], bytes[9]]),
        FORMAT_VERSION,
        "regenerate the golden model with the version bump"
    );
    let model = decode(&bytes, &path).expect("the golden model decodes");
    assert_eq!(model.header.name, "golden");
    assert_eq!(model.header.nodes as usize, model.map.nodes().len());
    assert_eq!(model.header.surfels as usize, model.map.surfels().len());
    assert!(model.map.surfels().iter().filter(|s| s.usable()).count() > 50);
    assert_eq!(encode(&model), bytes, "decoding then encoding reproduces the file");
    // Building it again gives the same statistics (map building has not drifted).
    let fresh = golden_model();
    assert_eq!(fresh.header.surfels, model.header.surfels);
    let (a, b) = (fresh.header.root, model.header.root);
    assert!((a.count - b.count).abs() < 1e-9 && (0..3).all(|k| (a.mean[k] - b.mean[k]).abs() < 1e-9), "{a:?} vs {b:?}");
}

fn expect_err(bytes: &[u8]) -> ModelError {
    match decode(bytes, Path::new("damaged.mrsm")) {
        Ok(_) => panic!("damaged file decoded"),
        Err(e) => e,
    }
}

#[test]
fn damaged_files_give_errors_that_say_what_is_wrong() {
    let bytes = encode(&golden_model());
    // Wrong file type.
    let e = expect_err(b"\x89PNG\r\n\x1a\n and then some");
    assert!(matches!(e, ModelError::BadMagic { .. }) && e.to_string().contains("not an mrsmap model"), "{e}");
    // Truncated anywhere: never a panic, always "truncated".
    let header_len = u32::from_le_bytes(bytes[10..14].try_into().expect("4 bytes")) as usize;
    for cut in [0, 3, 9, 12, 14, 14 + header_len / 2, 14 + header_len + 4, bytes.len() / 2, bytes.len() - 1] {
        let e = expect_err(&bytes[..cut]);
        assert!(matches!(e, ModelError::Truncated { .. }), "cut at {cut}: {e}");
        assert!(e.to_string().contains("truncated") && e.to_string().contains("damaged.mrsm"), "{e}");
    }
    // A flipped bit in the payload.
    let mut flipped = bytes.clone();
    let k = flipped.len() - 100;
    flipped[k] ^= 0x10;
    assert!(matches!(expect_err(&flipped), ModelError::Checksum { .. }));
    // A newer format version.
    let mut newer = bytes.clone();
    newer[8..10].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    let e = expect_err(&newer);
    assert!(matches!(e, ModelError::UnsupportedVersion { .. }) && e.to_string().contains("newer"), "{e}");
    // Garbage that passes the checksum: the header does not decode.
    let mut garbage = bytes.clone();
    for b in &mut garbage[14..14 + header_len] {
        *b = 0xFF;
    }
    reseal(&mut garbage);
    let e = expect_err(&garbage);
    assert!(matches!(e, ModelError::Decode { section: "header", .. }), "{e}");
}

#[test]
fn an_inconsistent_map_is_refused_on_load() {
    let model = golden_model();
    let mut parts = model.map.parts();
    parts.surfel_nodes[0] = u32::MAX - 7;
    let e = mrsmap::map::SurfelMap::restore(parts).expect_err("bad node index");
    assert!(e.to_string().contains("inconsistent"), "{e}");
}

#[test]
fn non_finite_statistics_are_refused_and_extreme_ones_do_not_panic() {
    // Found by fuzzing (fuzz/model_file): a NaN in a surfel's statistics reached the
    // eigen-decomposition of the normals and panicked there.
    let model = golden_model();
    for (field, value) in [(0, f64::NAN), (7, f64::INFINITY), (30, f64::NEG_INFINITY)] {
        let mut parts = model.map.parts();
        let s = &mut parts.stats[3];
        if field < 6 {
            s.sum[field] = value
        } else {
            s.scatter[field % 21] = value
        }
        let e = mrsmap::map::SurfelMap::restore(parts).expect_err("non-finite statistics");
        assert!(e.to_string().contains("surfel 3 has non-finite statistics"), "{e}");
    }
    let mut parts = model.map.parts();
    parts.view_dirs[5][1] = f32::NAN;
    assert!(mrsmap::map::SurfelMap::restore(parts).is_err());
    // Finite but absurd: sums whose products overflow. A map or an error, never a panic.
    let mut parts = model.map.parts();
    parts.stats[3].sum = [1e300; 6];
    parts.stats[4].scatter = [-1e300; 21];
    let _ = mrsmap::map::SurfelMap::restore(parts);
}
