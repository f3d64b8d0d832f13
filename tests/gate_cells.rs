//! The tracker's scene maps are the same whether the pixel gate is decided per whole
//! cell (`map::gate_cells`) or point by point: real teddy frames, the shipped teddy
//! model, its gate at the true pose and at poses moved so that the gate's boundary cuts
//! other parts of the image.

mod common;

use common::*;
use mrsmap::geometry::Pose;
use mrsmap::io::camera_file::read_camera;
use mrsmap::io::frames::FrameLoader;
use mrsmap::io::tum::TumDataset;
use mrsmap::map::{MapBuilder, MapCapacity, MapParams, SurfelMap};
use mrsmap::tracking::TrackerParams;
use nalgebra::{Translation3, UnitQuaternion};

/// `camera_from_object` of the teddy in the clip's first frame (robot_config/tracker.toml).
fn camera_from_object() -> Pose {
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(-0.13797, -0.25098, -0.79599, 0.53327));
    Pose::from_parts(Translation3::new(0.1923, 0.1253, 1.0402), q)
}

#[test]
fn a_scene_map_is_the_same_with_the_gate_decided_per_cell() {
    let model = mrsmap::model::load(&root().join("models/teddy.mrsm")).expect("the shipped model loads");
    let extent = model.extent().expect("extent");
    let params = TrackerParams::default();
    let map_params = MapParams {
        finest_resolution_m: model.map.params().finest_resolution_m,
        num_levels: model.map.num_levels(),
        ..params.map
    };
    let camera = read_camera(&fr3_camera_file()).expect("camera");
    let dataset = TumDataset::open(&teddy_clip()).expect("clip");
    let mut loader = FrameLoader::new(camera, false);
    let cam = loader.camera();
    let capacity = MapCapacity::for_image((cam.width * cam.height) as usize);
    let mut builder = MapBuilder::new(cam.width as usize, cam.height as usize, capacity.surfels);
    let (mut per_cell, mut per_point) =
        (SurfelMap::new(map_params, capacity).expect("map"), SurfelMap::new(map_params, capacity).expect("map"));
    // The true pose, and poses 3-6 cm and some degrees off it.
    let moves = [
        Pose::identity(),
        Pose::from_parts(Translation3::new(0.04, -0.03, 0.02), UnitQuaternion::from_euler_angles(0.1, -0.05, 0.2)),
        Pose::from_parts(Translation3::new(-0.06, 0.02, -0.03), UnitQuaternion::from_euler_angles(-0.15, 0.1, -0.1)),
    ];
    let mut decided = 0;
    for (i, entry) in dataset.frames.iter().enumerate().take(4) {
        let frame = loader.load(entry).expect("frame loads");
        for m in &moves {
            let object_from_camera = (camera_from_object() * *m).inverse();
            let region = extent.region(&object_from_camera, &frame.camera, &params);
            assert!(region.gate.as_ref().is_some_and(|g| g.cells.is_some()), "the teddy's gate is prepared for cells");
            let mut pointwise = region.clone();
            if let Some(g) = pointwise.gate.as_mut() {
                g.cells = None;
            }
            let a = builder.build_region(&frame, &region, &mut per_cell).expect("builds");
            let b = builder.build_region(&frame, &pointwise, &mut per_point).expect("builds");
            assert_eq!(a, b, "frame {i}: the same build report");
            assert!(per_cell.surfels().len() > 500, "frame {i}: a real scene ({} surfels)", per_cell.surfels().len());
            assert_eq!(per_cell.surfels(), per_point.surfels(), "frame {i}, move {m:?}: the same surfels");
            assert_eq!(per_cell.nodes(), per_point.nodes(), "frame {i}: the same nodes");
            assert_eq!(per_cell.stats(), per_point.stats(), "frame {i}: the same statistics");
            decided += 1;
        }
    }
    assert_eq!(decided, 12);
}
