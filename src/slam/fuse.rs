//! Fusion of the key views into one model (paper §5.1.3).

use super::system::Slam;
use super::volume::{Volume, VolumeError, VolumeSpec};
use crate::frame::RgbdFrame;
use crate::geometry::Pose;
use crate::map::{BuildReport, MapCapacity, MapError, MapParams, PlacedFrame, SurfelMap};
use nalgebra::{Point3, Vector3};
use thiserror::Error;

/// Why fusion failed.
#[derive(Debug, Error)]
pub enum FuseError {
    /// The volume of interest could not be set up.
    #[error("volume of interest: {0}")]
    Volume(#[from] VolumeError),
    /// The map could not be built (e.g. nothing inside the volume).
    #[error(transparent)]
    Map(#[from] MapError),
    /// There is no key view.
    #[error("no key view to fuse")]
    NoKeyViews,
    /// The map parameters are invalid.
    #[error(transparent)]
    Params(#[from] crate::map::MapParamsError),
}

/// The fused model and what went into it.
#[derive(Debug)]
pub struct Fused {
    /// The model, in the object frame (the world frame without a volume).
    pub map: SurfelMap,
    /// Where the model frame is in the world.
    pub world_from_model: Pose,
    /// The resolved volume of interest, if any.
    pub volume: Option<Volume>,
    /// Map-building counts.
    pub report: BuildReport,
}

impl Slam {
    /// Points of the key views in the world frame, every `stride`-th pixel.
    pub fn world_points(&self, stride: usize) -> Vec<Vector3<f64>> {
        let mut out = Vec::new();
        for (kv, pose) in self.key_views.iter().zip(&self.graph.vertices) {
            let cam = kv.camera;
            let (w, h) = (cam.width as usize, cam.height as usize);
            for v in (0..h).step_by(stride.max(1)) {
                for u in (0..w).step_by(stride.max(1)) {
                    let d = kv.depth[v * w + u];
                    if d == 0 {
                        continue;
                    }
                    if let Some((x, y)) = cam.unproject_normalized(u as f64, v as f64) {
                        let z = d as f64 * cam.depth_scale_m;
                        out.push((pose * Point3::new(x * z, y * z, z)).coords);
                    }
                }
            }
        }
        out
    }

    /// Fuses every key view at its optimised pose into one map (§5.1.3). With a volume
    /// of interest, the model is expressed in the object frame and only points inside
    /// the volume enter; the support plane of a prism is fitted to the key views' points.
    /// View directions are smoothed; contours and level-boundary exclusion, which
    /// describe a single view, are not used.
    pub fn fuse(&mut self, volume: Option<&VolumeSpec>) -> Result<Fused, FuseError> {
        if self.key_views.is_empty() {
            return Err(FuseError::NoKeyViews);
        }
        let volume = match volume {
            Some(spec) => {
                let points = self.world_points(4);
                let cameras = self.graph.vertices.iter().map(|p| p.translation.vector).sum::<Vector3<f64>>()
                    / self.graph.vertices.len() as f64;
                let center = points.iter().sum::<Vector3<f64>>() / points.len().max(1) as f64;
                Some(spec.resolve(&points, &(cameras - center))?)
            }
            None => None,
        };
        let world_from_model = volume.as_ref().map(|v| v.world_from_object).unwrap_or_else(Pose::identity);
        let model_from_world = world_from_model.inverse();
        let frames: Vec<RgbdFrame> = self
            .key_views
            .iter()
            .filter_map(|kv| RgbdFrame::new(kv.stamp_ns, kv.camera, &kv.rgb, &kv.depth).ok())
            .collect();
        let views: Vec<PlacedFrame> = frames
            .iter()
            .zip(&self.graph.vertices)
            .map(|(frame, world_from_camera)| PlacedFrame {
                frame,
                map_from_camera: model_from_world * world_from_camera,
            })
            .collect();
        let params = MapParams {
            smooth_view_dirs: true,
            mark_foreground_borders: false,
            exclude_level_boundaries: false,
            ..self.params().map
        };
        let nodes: usize = self.key_views.iter().map(|k| k.map.nodes().len()).sum();
        let surfels: usize = self.key_views.iter().map(|k| k.map.surfels().len()).sum();
        let capacity = MapCapacity { nodes: nodes + 4096, surfels: surfels * 2 + 8192 };
        let mut map = SurfelMap::new(params, capacity)?;
        let shape = volume.as_ref().map(|v| v.shape.clone());
        let keep = move |p: &Vector3<f32>| shape.as_ref().is_none_or(|s| s.contains(&p.cast::<f64>()));
        let report = self.builder.fuse(&views, &keep, &mut map)?;
        Ok(Fused { map: map.to_compact(), world_from_model, volume, report })
    }
}
