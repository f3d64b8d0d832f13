//! Pictures of tracking: each frame's colour image with every tracked object's model
//! drawn at its estimated pose (`track --dataset --overlay DIR`), coloured by what the
//! depth image says about each model surface, as the free-space check judges it
//! (`tracking::free_space`): green where the measured depth agrees, red where the camera
//! sees through the model (the pose is wrong there), blue where something nearer hides
//! it, grey without a measurement. A green frame around the image: every object tracked
//! in this frame; red: at least one is not (lost, initialising, or its pose held).

use crate::frame::RgbdFrame;
use crate::geometry::Pose;
use crate::map::SurfelMap;
use crate::tracking::free_space::{DepthTest, Evidence};
use nalgebra::{Point3, Vector3};

const SUPPORTED: [u8; 3] = [40, 220, 60];
const VIOLATED: [u8; 3] = [235, 40, 40];
const OCCLUDED: [u8; 3] = [60, 120, 255];
const UNMEASURED: [u8; 3] = [170, 170, 170];
/// Width of the status frame around the image (pixels).
const BORDER_PX: usize = 4;
/// The colour image is dimmed to this fraction so the model stands out.
const DIM: f32 = 0.6;

/// An object's model surfaces to draw: the finest valid surfel of every region
/// ([`SurfelMap::leaf_surfels`]), with its normal and cell size (object frame).
#[derive(Debug, Clone)]
pub struct ModelPoints {
    points: Vec<(Vector3<f32>, Vector3<f32>, f32)>,
}

impl ModelPoints {
    /// Gathers the points of `model`.
    pub fn new(model: &SurfelMap) -> Self {
        let points = model
            .leaf_surfels()
            .into_iter()
            .map(|s| {
                let surfel = &model.surfels()[s as usize];
                (surfel.mean, model.normals()[s as usize], model.resolution(surfel.level as usize) as f32)
            })
            .collect();
        ModelPoints { points }
    }
}

/// Draws into `rgb` (the frame's size, RGB8) the frame's colour image with every model of
/// `objects` at its pose (`None`: not drawn, the object is not tracked in this frame);
/// `margin_m` is the depth tolerance of the free-space check.
pub fn draw(frame: &RgbdFrame, objects: &[(&ModelPoints, Option<Pose>)], margin_m: f64, rgb: &mut Vec<u8>) {
    rgb.clear();
    rgb.extend(frame.rgb.iter().map(|&c| (f32::from(c) * DIM) as u8));
    let camera = &frame.camera;
    let (w, h) = (frame.width(), frame.height());
    // Far surfaces first, so that nearer ones are drawn over them.
    let mut discs: Vec<(f32, f64, f64, f64, [u8; 3])> = Vec::new();
    for (model, pose) in objects {
        let Some(camera_from_object) = pose else { continue };
        let test = DepthTest::new(frame, camera_from_object, margin_m);
        let project = |p: &Vector3<f32>| camera.project(&Point3::from(p.cast::<f64>()));
        for (mean, normal, size) in &model.points {
            let Some((p, (u, v), evidence)) = test.judge(frame, mean, normal, project) else { continue };
            let colour = match evidence {
                Evidence::Supported => SUPPORTED,
                Evidence::Violated => VIOLATED,
                Evidence::Occluded => OCCLUDED,
                Evidence::NoMeasurement => UNMEASURED,
            };
            // A third of the cell's size, at least a pixel: neighbours stay apart.
            let radius = (camera.intrinsics.fx * f64::from(*size) / f64::from(p.z) / 3.0).max(1.0);
            discs.push((p.z, u, v, radius, colour));
        }
    }
    discs.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (_, u, v, r, colour) in discs {
        let (u0, u1) = ((u - r).floor().max(0.0) as usize, ((u + r).ceil().max(0.0) as usize).min(w - 1));
        let (v0, v1) = ((v - r).floor().max(0.0) as usize, ((v + r).ceil().max(0.0) as usize).min(h - 1));
        for y in v0..=v1 {
            for x in u0..=u1 {
                let (dx, dy) = (x as f64 - u, y as f64 - v);
                if dx * dx + dy * dy <= r * r {
                    rgb[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&colour);
                }
            }
        }
    }
    let all_tracked = objects.iter().all(|(_, pose)| pose.is_some());
    let border = if all_tracked { SUPPORTED } else { VIOLATED };
    for y in 0..h {
        for x in 0..w {
            if x < BORDER_PX || y < BORDER_PX || x + BORDER_PX >= w || y + BORDER_PX >= h {
                rgb[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&border);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{CameraModel, NO_DISTORTION, PinholeIntrinsics};
    use nalgebra::{Translation3, UnitQuaternion};

    /// A model of one surfel facing the camera (normal −z in the camera frame) at 1 m.
    fn one_point() -> ModelPoints {
        ModelPoints { points: vec![(Vector3::zeros(), Vector3::new(0.0, 0.0, -1.0), 0.0125)] }
    }

    fn frame_with_depth<'a>(rgb: &'a [u8], depth: &'a [u16]) -> RgbdFrame<'a> {
        let camera = CameraModel {
            width: 40,
            height: 30,
            intrinsics: PinholeIntrinsics { fx: 50.0, fy: 50.0, cx: 20.0, cy: 15.0 },
            distortion: NO_DISTORTION,
            depth_scale_m: 0.001,
        };
        RgbdFrame::new(7, camera, rgb, depth).expect("frame")
    }

    #[test]
    fn the_model_is_coloured_by_the_depth_at_its_pixels_and_the_border_by_the_status() {
        let rgb = vec![100u8; 40 * 30 * 3];
        let at = Some(Pose::from_parts(Translation3::new(0.0, 0.0, 1.0), UnitQuaternion::identity()));
        let model = one_point();
        let centre = |out: &[u8]| out[3 * (15 * 40 + 20)..3 * (15 * 40 + 20) + 3].to_vec();
        let mut out = Vec::new();
        for (depth_mm, expected) in [(1000, SUPPORTED), (1500, VIOLATED), (600, OCCLUDED), (0, UNMEASURED)] {
            let depth = vec![depth_mm; 40 * 30];
            draw(&frame_with_depth(&rgb, &depth), &[(&model, at)], 0.02, &mut out);
            assert_eq!(centre(&out), expected, "depth {depth_mm} mm");
            assert_eq!(out[..3], SUPPORTED, "tracked: a green frame");
        }
        // Not tracked: nothing drawn, the image dimmed, a red frame.
        let depth = vec![1000; 40 * 30];
        draw(&frame_with_depth(&rgb, &depth), &[(&model, None)], 0.02, &mut out);
        assert_eq!(centre(&out), [60, 60, 60]);
        assert_eq!(out[..3], VIOLATED);
        assert_eq!(out.len(), rgb.len());
    }

    #[test]
    fn surfaces_facing_away_or_behind_the_camera_are_not_drawn() {
        let rgb = vec![100u8; 40 * 30 * 3];
        let depth = vec![1000; 40 * 30];
        let mut out = Vec::new();
        let turned =
            Pose::from_parts(Translation3::new(0.0, 0.0, 1.0), UnitQuaternion::from_euler_angles(0.0, 3.0, 0.0));
        let behind = Pose::from_parts(Translation3::new(0.0, 0.0, -1.0), UnitQuaternion::identity());
        for pose in [turned, behind] {
            draw(&frame_with_depth(&rgb, &depth), &[(&one_point(), Some(pose))], 0.02, &mut out);
            assert_eq!(out[3 * (15 * 40 + 20)..3 * (15 * 40 + 20) + 3], [60, 60, 60]);
        }
    }
}
