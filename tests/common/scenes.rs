//! Rendered scenes and object models for the tracking tests.

use mrsmap::frame::RgbdFrame;
use mrsmap::geometry::se3::left_increment;
use mrsmap::geometry::{CameraModel, Pose};
use mrsmap::map::{MapBuilder, MapCapacity, MapParams, PlacedFrame, SurfelMap};
use mrsmap::model::RootStats;
use mrsmap::slam::VolumeShape;
use mrsmap::synthetic::RenderTarget;
use mrsmap::tracking::{ModelExtent, ObjectModel, PoseEstimate, SearchRegion, TrackingStatus};
use nalgebra::{Matrix3, Translation3, UnitQuaternion, Vector3, Vector6};
use std::ops::Range;

/// A model as the mapping tool makes it, fused from `views` at their known poses, of
/// what lies in the box of `center` and `half` extents (the first camera's frame), in
/// an object frame at `origin` (the first camera's frame shifted; the volume is a box
/// centred there).
pub fn object_model_in(
    views: &[(&RenderTarget, Pose)],
    center: Vector3<f64>,
    half: Vector3<f64>,
    origin: Vector3<f64>,
) -> ObjectModel {
    let first_camera_from_object = Pose::from_parts(Translation3::from(origin), UnitQuaternion::identity());
    let center = center - origin;
    let views: Vec<(&RenderTarget, Pose)> =
        views.iter().map(|&(t, p)| (t, first_camera_from_object.inverse() * p)).collect();
    let cam = views[0].0.camera;
    let capacity = MapCapacity { nodes: 200_000, surfels: 400_000 };
    let mut map =
        SurfelMap::new(MapParams { smooth_view_dirs: true, ..MapParams::default() }, capacity).expect("params");
    let inside = move |p: &Vector3<f32>| (p.cast::<f64>() - center).iter().zip(half.iter()).all(|(d, h)| d.abs() <= *h);
    let frames: Vec<RgbdFrame> =
        views.iter().map(|(t, _)| RgbdFrame::new(0, cam, &t.rgb, &t.depth).expect("frame")).collect();
    let placed: Vec<PlacedFrame> =
        frames.iter().zip(&views).map(|(frame, (_, pose))| PlacedFrame { frame, map_from_camera: *pose }).collect();
    MapBuilder::new(cam.width as usize, cam.height as usize, capacity.surfels)
        .fuse(&placed, &inside, &mut map)
        .expect("the objects are in view");
    let map = map.to_compact();
    let root = RootStats::of(&map);
    let [xx, xy, xz, yy, yz, zz] = root.covariance;
    let (lo, hi) = map
        .surfels()
        .iter()
        .filter(|s| s.usable())
        .fold((Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY)), |(lo, hi), s| {
            (lo.inf(&s.mean.cast()), hi.sup(&s.mean.cast()))
        });
    // A box volume is centred on the object frame's origin: one that reaches the objects
    // and stops above the table and before the walls.
    let reach = center.abs() + half;
    let extent = ModelExtent::new(
        Vector3::from(root.mean),
        Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz),
        Some(&VolumeShape::Box { half_extents: [reach.x, reach.y, reach.z] }),
        (lo, hi),
    )
    .expect("extent");
    ObjectModel {
        name: "objects".into(),
        map,
        extent,
        initial_camera_from_object: first_camera_from_object,
        search: SearchRegion { translation_m: 0.03, yaw_rad: 0.1 },
        color_term: None,
    }
}

/// A pose estimate to be overwritten (the tracker's output slots).
pub fn blank() -> PoseEstimate {
    PoseEstimate {
        stamp_ns: 0,
        object: 0,
        status: TrackingStatus::Initialising,
        camera_from_object: Pose::identity(),
        covariance_ros: nalgebra::Matrix6::identity(),
        quality: 0.0,
        free_space: 0.0,
        associations: 0,
        iterations: 0,
        bad_frames: 0,
    }
}

/// A table with two groups, each a box and a sphere, left and right of the middle.
pub fn two_groups() -> mrsmap::synthetic::Mesh {
    use mrsmap::synthetic::scene::{ColorField, add_box, add_sphere, add_table_and_back_wall};
    let field = ColorField::new(&mut mrsmap::synthetic::Pcg32::new(7), 12);
    let mut mesh = mrsmap::synthetic::Mesh::default();
    let step = 0.01;
    add_table_and_back_wall(&mut mesh, step, &field);
    for side in [-1.0, 1.0] {
        add_box(&mut mesh, Vector3::new(side * 0.35 - 0.1, 0.3, 0.9), Vector3::new(0.2, 0.2, 0.15), step, &field);
        add_sphere(&mut mesh, Vector3::new(side * 0.15, 0.38, 0.8), 0.12, step, &field);
    }
    mesh
}

/// [`two_groups`] seen at QVGA along 12 frames (2 mm up, 1.2 cm forward and 0.11° about
/// the vertical per frame), with the right group hidden (no depth right of the gap
/// between the groups) in the frames [`TwoGroupsRun::HIDDEN`].
pub struct TwoGroupsRun {
    pub cam: CameraModel,
    /// `world_from_camera` of each frame (world = the first camera's frame).
    pub poses: Vec<Pose>,
    pub targets: Vec<RenderTarget>,
    /// The depth images, the right group's pixels cleared in the hidden frames.
    pub depths: Vec<Vec<u16>>,
}

impl TwoGroupsRun {
    /// The frames without the right group.
    pub const HIDDEN: Range<usize> = 4..10;

    pub fn new() -> Self {
        let mesh = two_groups();
        let cam = crate::common::vga().halved();
        let poses: Vec<Pose> =
            (0..12).map(|k| left_increment(&(Vector6::new(0.0, -0.002, 0.012, 0.0, 0.002, 0.0) * k as f64))).collect();
        let targets: Vec<RenderTarget> = poses.iter().map(|p| crate::common::render_frame(&mesh, cam, p)).collect();
        let depths = targets
            .iter()
            .enumerate()
            .map(|(k, t)| {
                let mut depth = t.depth.clone();
                if Self::HIDDEN.contains(&k) {
                    for (i, d) in depth.iter_mut().enumerate() {
                        if i % cam.width as usize >= 160 {
                            *d = 0;
                        }
                    }
                }
                depth
            })
            .collect();
        TwoGroupsRun { cam, poses, targets, depths }
    }

    /// The models of the left and the right group, fused from the first and the last
    /// frame, each in a frame at its centre, with `search` as their search region.
    pub fn models(&self, search: SearchRegion) -> (ObjectModel, ObjectModel) {
        let last = self.targets.len() - 1;
        let views = [(&self.targets[0], self.poses[0]), (&self.targets[last], self.poses[last])];
        let (y, z) = ((0.335, 0.155), (0.88, 0.22));
        let group = |x: f64, name: &str| {
            let center = Vector3::new(x, y.0, z.0);
            ObjectModel {
                name: name.into(),
                search,
                ..object_model_in(&views, center, Vector3::new(0.235, y.1, z.1), center)
            }
        };
        (group(-0.235, "left"), group(0.235, "right"))
    }

    /// Frame `k` (the right group hidden in [`Self::HIDDEN`]), stamped `stamp_ns`.
    pub fn frame(&self, k: usize, stamp_ns: u64) -> RgbdFrame<'_> {
        RgbdFrame::new(stamp_ns, self.cam, &self.targets[k].rgb, &self.depths[k]).expect("rendered frame")
    }
}
