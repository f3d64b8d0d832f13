//! Camera paths for synthetic sequences: stretches that circle a point of interest
//! while looking at it (a robot's head or arm camera moving around a table), with an
//! optional seeded shake (a camera held by a moving arm is never quite still).

use super::scene::Pcg32;
use crate::geometry::Pose;
use crate::geometry::se3::left_increment;
use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3, Vector6};

/// One stretch of a path: over `seconds` the camera moves at constant speed in
/// cylindrical coordinates about the point it looks at, from the first value of each
/// pair to the second (world frame, z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Duration (s), > 0.
    pub seconds: f64,
    /// Direction from the point to the camera about the world z axis (degrees; 0: +x).
    pub azimuth_deg: [f64; 2],
    /// Horizontal distance from the point (m).
    pub distance_m: [f64; 2],
    /// Height above the point (m).
    pub height_m: [f64; 2],
    /// The point looked at (world frame, m).
    pub look_at: [Vector3<f64>; 2],
}

/// A seeded shake added to the path: per axis a sum of three slow sines (0.3–2 Hz) of
/// random phase whose root mean square is the amplitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shake {
    /// RMS translation per axis (m).
    pub translation_m: f64,
    /// RMS rotation per axis (degrees).
    pub rotation_deg: f64,
    /// Seed of the phases and frequencies.
    pub seed: u64,
}

/// A path: stretches one after the other, each starting where the one before ended if
/// the description says so (this type does not check it).
#[derive(Debug, Clone, PartialEq)]
pub struct CameraPath {
    /// The stretches, in order.
    pub segments: Vec<Segment>,
    /// Shake added to every pose.
    pub shake: Option<Shake>,
}

/// Three sines per axis of the shake: (frequency Hz, phase, weight).
type Waves = [[(f64, f64, f64); 3]; 6];

impl CameraPath {
    /// Total duration (s).
    pub fn duration_s(&self) -> f64 {
        self.segments.iter().map(|s| s.seconds).sum()
    }

    /// `world_from_camera` (optical frame: x right, y down, z forward) at time `t_s`
    /// from the start, clamped to the path.
    pub fn world_from_camera(&self, t_s: f64) -> Pose {
        let (segment, f) = self.locate(t_s);
        let lerp = |a: [f64; 2]| a[0] + (a[1] - a[0]) * f;
        let target = segment.look_at[0] + (segment.look_at[1] - segment.look_at[0]) * f;
        let azimuth = lerp(segment.azimuth_deg).to_radians();
        let eye = target
            + Vector3::new(
                lerp(segment.distance_m) * azimuth.cos(),
                lerp(segment.distance_m) * azimuth.sin(),
                lerp(segment.height_m),
            );
        let pose = look_at(&eye, &target);
        match &self.shake {
            Some(shake) => pose * left_increment(&shake_at(shake, &waves(shake.seed), t_s)),
            None => pose,
        }
    }

    /// The stretch at time `t_s` and how far along it is (0–1).
    fn locate(&self, t_s: f64) -> (&Segment, f64) {
        let mut start = 0.0;
        for (i, s) in self.segments.iter().enumerate() {
            if t_s < start + s.seconds || i + 1 == self.segments.len() {
                return (s, ((t_s - start) / s.seconds).clamp(0.0, 1.0));
            }
            start += s.seconds;
        }
        unreachable!("a path has at least one stretch")
    }
}

/// The camera at `eye` looking at `target`, its x axis level (world z up). Looking
/// straight down, x is the world's x.
pub fn look_at(eye: &Vector3<f64>, target: &Vector3<f64>) -> Pose {
    let z = (target - eye).normalize();
    let level = z.cross(&Vector3::z());
    let x = if level.norm() > 1e-9 { level.normalize() } else { Vector3::x() };
    let y = z.cross(&x);
    let rotation = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    Pose::from_parts(Translation3::from(*eye), UnitQuaternion::from_rotation_matrix(&rotation))
}

fn waves(seed: u64) -> Waves {
    let mut rng = Pcg32::new(seed);
    std::array::from_fn(|_| {
        let raw: [(f64, f64, f64); 3] =
            std::array::from_fn(|_| (rng.uniform(0.3, 2.0), rng.uniform(0.0, std::f64::consts::TAU), 1.0));
        // Sines of different frequencies are uncorrelated: RMS = sqrt(Σ w²/2).
        let norm = (raw.iter().map(|w| w.2 * w.2 / 2.0).sum::<f64>()).sqrt();
        raw.map(|(f, p, w)| (f, p, w / norm))
    })
}

/// The shake's tangent vector (camera frame) at `t_s`.
fn shake_at(shake: &Shake, waves: &Waves, t_s: f64) -> Vector6<f64> {
    Vector6::from_fn(|axis, _| {
        let amplitude = if axis < 3 { shake.translation_m } else { shake.rotation_deg.to_radians() };
        amplitude * waves[axis].iter().map(|(f, p, w)| w * (std::f64::consts::TAU * f * t_s + p).sin()).sum::<f64>()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    fn orbit() -> CameraPath {
        let look = Vector3::new(0.1, -0.2, 0.75);
        CameraPath {
            segments: vec![
                Segment {
                    seconds: 2.0,
                    azimuth_deg: [0.0, 90.0],
                    distance_m: [0.8, 0.8],
                    height_m: [0.4, 0.4],
                    look_at: [look, look],
                },
                Segment {
                    seconds: 1.0,
                    azimuth_deg: [90.0, 90.0],
                    distance_m: [0.8, 0.4],
                    height_m: [0.4, 0.2],
                    look_at: [look, look],
                },
            ],
            shake: None,
        }
    }

    #[test]
    fn the_camera_looks_at_the_point_level_and_upright() {
        let path = orbit();
        for t in [0.0, 0.7, 2.0, 2.5, 3.0, 9.0] {
            let pose = path.world_from_camera(t);
            let in_camera = pose.inverse() * Point3::from(Vector3::new(0.1, -0.2, 0.75));
            assert!(in_camera.x.abs() < 1e-9 && in_camera.y.abs() < 1e-9 && in_camera.z > 0.0, "t = {t}");
            let x_axis = pose.rotation * Vector3::x();
            let y_axis = pose.rotation * Vector3::y();
            assert!(x_axis.z.abs() < 1e-9, "x stays level");
            assert!(y_axis.z < 0.0, "image y points down");
        }
        let start = path.world_from_camera(0.0).translation.vector;
        assert!((start - Vector3::new(0.9, -0.2, 1.15)).norm() < 1e-12);
        let end = path.world_from_camera(3.0).translation.vector;
        assert!((end - Vector3::new(0.1, 0.2, 0.95)).norm() < 1e-12);
        assert_eq!(path.duration_s(), 3.0);
    }

    #[test]
    fn shake_has_its_rms_and_is_smooth() {
        let shake = Shake { translation_m: 0.004, rotation_deg: 0.5, seed: 7 };
        let w = waves(7);
        let samples: Vec<Vector6<f64>> = (0..20_000).map(|k| shake_at(&shake, &w, k as f64 * 0.01)).collect();
        let rms = |axis: usize| (samples.iter().map(|s| s[axis] * s[axis]).sum::<f64>() / samples.len() as f64).sqrt();
        assert!((rms(0) / 0.004 - 1.0).abs() < 0.15, "translation RMS {}", rms(0));
        assert!((rms(4) / 0.5f64.to_radians() - 1.0).abs() < 0.15, "rotation RMS {}", rms(4));
        // 33 ms apart the shake moves by a small fraction of its amplitude.
        let step = (shake_at(&shake, &w, 1.033) - shake_at(&shake, &w, 1.0)).fixed_rows::<3>(0).norm();
        assert!(step < 0.002, "{step}");
    }
}
