//! Parameters of map building (paper §3) and the capacities of its arenas.

use thiserror::Error;

/// The most resolution levels a map can have.
pub const MAX_LEVELS: usize = 8;

/// The least `min_points` that [`MapParams::min_points_for_image`] scales to: a 3-D
/// covariance from fewer points is too rough to register with.
pub const SCALED_MIN_POINTS_FLOOR: f64 = 5.0;

/// Pixels of a VGA image (640 × 480), the size the paper's thresholds are for.
const VGA_PIXELS: f64 = 640.0 * 480.0;

/// Why map parameters were rejected.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MapParamsError {
    /// A parameter is out of its valid range.
    #[error("map parameter {name} = {value} is out of range ({expected})")]
    OutOfRange {
        /// Parameter name.
        name: &'static str,
        /// The value given.
        value: f64,
        /// What is allowed.
        expected: &'static str,
    },
}

/// How a map is built from an image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapParams {
    /// Edge of the finest cells (m). Paper: 0.0125.
    pub finest_resolution_m: f64,
    /// Number of resolution levels; level `l` has cells of `finest · 2^l`. Default 6
    /// (1.25 cm … 40 cm); points whose distance-dependent resolution is coarser than the
    /// coarsest level are not inserted.
    pub num_levels: usize,
    /// Distance dependency λ: a point at range `r` is inserted down to cells of edge
    /// about `2 λ r²` (§3.3, the disparity noise of RGB-D cameras). Paper: 0.01.
    pub lambda: f64,
    /// A surfel takes part in registration from this many points on (§3.1). Paper: 10.
    pub min_points: f64,
    /// A surfel stops growing at this many points (§3.1). Paper: 10 000.
    pub max_points: f64,
    /// Add each pixel to every surfel whose view direction is within 67.5° of its ray
    /// (true), or only to the closest one (false, the odometry setting).
    pub smooth_view_dirs: bool,
    /// Estimate normals from the statistics of the 3×3×3 neighbourhood (true) or of the
    /// surfel alone.
    pub smooth_normals: bool,
    /// Depth-jump ratio for virtual and foreground borders (§3.4): a jump is a pair of
    /// neighbouring valid pixels whose ranges differ by more than this factor. Paper: 0.9.
    pub depth_jump_ratio: f64,
    /// Mark the nearer pixel of depth jumps as foreground contour (§3.4); contour surfels
    /// only match contour surfels.
    pub mark_foreground_borders: bool,
    /// Keep out of registration the cells cut by the range at which points stop being
    /// inserted at their level: they hold only the nearer points, and that part moves
    /// with the camera, biasing the mean (measured: odometry RPE median teddy 2.01 →
    /// 1.89 mm, fr1_xyz RMSE 2.97 → 2.78 mm). For maps built from one frame (the sensor
    /// at the origin); fused maps set it off.
    pub exclude_level_boundaries: bool,
    /// Weight of the neighbours' descriptors when smoothing shape–texture descriptors (§3.2).
    pub descriptor_neighbor_weight: f32,
    /// Luminance and chrominance differences at which texture bins saturate (§3.2).
    pub texture_bin_threshold: f32,
    /// Keep the colour rows of the joint 6-D scatter (§3.1): the colour covariance and
    /// its cross-covariance with position. Maps that are saved or fused (key views,
    /// models) need them. Registration does not read them (it uses the position
    /// covariance and the mean colour), so odometry and the tracker's scene maps turn
    /// this off: each pixel then adds to 13 sums instead of 28 (docs/benchmarks-history.md, stop
    /// 40), and [`SurfelMap::stats`](super::SurfelMap::stats) holds zero colour rows.
    pub color_scatter: bool,
}

impl Default for MapParams {
    fn default() -> Self {
        MapParams {
            finest_resolution_m: 0.0125,
            num_levels: 6,
            lambda: 0.01,
            min_points: 10.0,
            max_points: 10_000.0,
            smooth_view_dirs: false,
            smooth_normals: true,
            depth_jump_ratio: 0.9,
            mark_foreground_borders: true,
            exclude_level_boundaries: true,
            descriptor_neighbor_weight: 0.1,
            texture_bin_threshold: 0.1,
            color_scatter: true,
        }
    }
}

impl MapParams {
    /// Checks ranges; the error names the first bad parameter.
    pub fn validate(&self) -> Result<(), MapParamsError> {
        let check = |name: &'static str, value: f64, ok: bool, expected: &'static str| {
            if ok { Ok(()) } else { Err(MapParamsError::OutOfRange { name, value, expected }) }
        };
        let r = self.finest_resolution_m;
        check("finest_resolution_m", r, r.is_finite() && (1e-4..=10.0).contains(&r), "1e-4 ..= 10")?;
        let n = self.num_levels as f64;
        check("num_levels", n, (1..=MAX_LEVELS).contains(&self.num_levels), "1 ..= 8")?;
        check("lambda", self.lambda, self.lambda.is_finite() && self.lambda > 0.0, "> 0")?;
        check("min_points", self.min_points, self.min_points >= 4.0, ">= 4")?;
        check("max_points", self.max_points, self.max_points >= self.min_points, ">= min_points")?;
        let j = self.depth_jump_ratio;
        check("depth_jump_ratio", j, j > 0.0 && j < 1.0, "0 < ratio < 1")?;
        let w = self.descriptor_neighbor_weight as f64;
        check("descriptor_neighbor_weight", w, (0.0..=1.0).contains(&w), "0 ..= 1")?;
        let t = self.texture_bin_threshold as f64;
        check("texture_bin_threshold", t, t > 0.0 && t.is_finite(), "> 0")?;
        Ok(())
    }

    /// Cell edge (m) at `level`.
    pub fn resolution(&self, level: usize) -> f64 {
        self.finest_resolution_m * (1u64 << level) as f64
    }

    /// Squared ranges at which the target level steps up: a point with squared range
    /// `r2` goes down to level `#{k : thresholds[k] ≤ r2}`. The level is the rounded
    /// `log2(2 λ r² / finest)`, i.e. level ≥ k iff `2 λ r² ≥ finest · 2^(k − ½)`.
    pub fn level_thresholds_r2(&self) -> [f32; MAX_LEVELS] {
        let mut t = [f32::INFINITY; MAX_LEVELS];
        for (k, tk) in t.iter_mut().enumerate().take(self.num_levels) {
            let step = k as f64 + 1.0;
            *tk = (self.finest_resolution_m * 2f64.powf(step - 0.5) / (2.0 * self.lambda)) as f32;
        }
        t
    }

    /// `min_points` for an image of `pixels` pixels: scaled by its pixel count against
    /// the VGA images the paper's threshold is for (640 × 480), not above `min_points`
    /// and not below [`SCALED_MIN_POINTS_FLOOR`] (or `min_points` when that is lower).
    ///
    /// Why: a cell's size in metres follows its range (§3.3) whatever the image, so a
    /// QVGA image puts a quarter of the points a VGA one puts in each cell; with the
    /// same threshold a small object's finest cells fall below it (docs/evaluation.md,
    /// "Small objects at QVGA"). Not in the paper, which uses VGA images only.
    pub fn min_points_for_image(&self, pixels: usize) -> f64 {
        let floor = SCALED_MIN_POINTS_FLOOR.min(self.min_points);
        (self.min_points * pixels as f64 / VGA_PIXELS).clamp(floor, self.min_points)
    }

    /// A λ at most an octave below `self.lambda` (cells at most one level finer than
    /// the rule's) at which every point with a range in `near ..= far` (m) goes to one
    /// level, the finest such; `self.lambda` when the ranges span more than a factor √2,
    /// the band of one level, or no such λ exists.
    ///
    /// Why: the rule of §3.3 rounds each point's level to the nearest, so a small object
    /// ends up on a coarser level from some range on, or split across two at the range
    /// where the level steps: it then loses the cells along the step
    /// ([`MapParams::exclude_level_boundaries`]) and its far part to cells too coarse to
    /// leave it enough surfels to register (docs/evaluation.md, "Small objects on one
    /// level"). Rounding such an object's points down instead, all together, keeps its
    /// cells within a factor 2 of `2 λ r²` (the rule keeps them within √2).
    pub fn lambda_for_one_level(&self, near: f64, far: f64) -> f64 {
        if !(near > 0.0 && far.is_finite() && near <= far && far * far < 2.0 * near * near) {
            return self.lambda;
        }
        // A point goes to level `k` or finer iff `r² < c_k / λ` (the thresholds of
        // `level_thresholds_r2`).
        let c = |k: usize| self.finest_resolution_m * 2f64.powf(k as f64 + 0.5) / 2.0;
        for k in 0..self.num_levels {
            // All at level k: the farthest below step k (by a thousandth, beyond the
            // single-precision thresholds), the nearest beyond step k − 1.
            let largest = (c(k) / (far * far * 1.001)).min(self.lambda);
            let least = if k == 0 { 0.0 } else { c(k - 1) / (near * near) }.max(0.5 * self.lambda);
            if largest >= least {
                return largest;
            }
        }
        self.lambda
    }
}

/// Capacities of the map arenas, fixed when a map is created.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MapCapacity {
    /// Octree nodes over all levels.
    pub nodes: usize,
    /// Surfels over all nodes.
    pub surfels: usize,
}

impl MapCapacity {
    /// Capacities for maps built from images of `pixels` pixels: generous for real
    /// RGB-D frames (a VGA frame of a cluttered scene needs about 15 000 nodes).
    pub fn for_image(pixels: usize) -> Self {
        let nodes = (pixels / 6).max(4096);
        MapCapacity { nodes, surfels: nodes * 2 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The level a point at range `r` goes to under `params` (as the aggregation decides).
    fn level(params: &MapParams, r: f64) -> usize {
        let t = params.level_thresholds_r2();
        let r2 = (r * r) as f32;
        (0..MAX_LEVELS).take_while(|&k| r2 >= t[k]).count()
    }

    #[test]
    fn min_points_scale_with_the_image_between_the_floor_and_the_papers() {
        let p = MapParams::default();
        assert_eq!(p.min_points_for_image(640 * 480), 10.0);
        assert_eq!(p.min_points_for_image(1280 * 960), 10.0, "never above the paper's");
        assert_eq!(p.min_points_for_image(480 * 360), 5.625);
        assert_eq!(p.min_points_for_image(320 * 240), SCALED_MIN_POINTS_FLOOR);
        assert_eq!(p.min_points_for_image(0), SCALED_MIN_POINTS_FLOOR);
        let few = MapParams { min_points: 4.0, ..p };
        assert_eq!(few.min_points_for_image(320 * 240), 4.0, "never above the configured");
    }

    #[test]
    fn a_small_object_goes_to_one_level_the_finer() {
        let p = MapParams::default();
        // Level 0 ends at 0.94 m at λ = 0.01: an object over 0.85–1.05 m straddles it.
        assert_ne!(level(&p, 0.85), level(&p, 1.05));
        let fitted = MapParams { lambda: p.lambda_for_one_level(0.85, 1.05), ..p };
        assert!(fitted.lambda < p.lambda && fitted.lambda >= 0.5 * p.lambda, "{}", fitted.lambda);
        assert_eq!((level(&fitted, 0.85), level(&fitted, 1.05)), (0, 0));
        // All on the coarser level at λ: moved to the finer one.
        assert_eq!((level(&p, 1.0), level(&p, 1.2)), (1, 1));
        let fitted = MapParams { lambda: p.lambda_for_one_level(1.0, 1.2), ..p };
        assert_eq!((level(&fitted, 1.0), level(&fitted, 1.2)), (0, 0));
        // Already all on the finest level: λ unchanged.
        assert_eq!(p.lambda_for_one_level(0.5, 0.6), p.lambda);
    }

    #[test]
    fn the_lambda_is_at_most_an_octave_lower() {
        let p = MapParams::default();
        // 1.5–1.6 m is on level 2 at λ; level 0 would need λ below half of it: level 1.
        assert_eq!((level(&p, 1.5), level(&p, 1.6)), (2, 2));
        let fitted = MapParams { lambda: p.lambda_for_one_level(1.5, 1.6), ..p };
        assert_eq!((level(&fitted, 1.5), level(&fitted, 1.6)), (1, 1));
        assert!(fitted.lambda >= 0.5 * p.lambda);
        // Every object within one band ends up on one level, never a coarser one.
        for i in 0..400 {
            let near = 0.3 + 0.01 * i as f64;
            for ratio in [1.0, 1.1, 1.3, 1.41] {
                let far = near * ratio;
                let fitted = MapParams { lambda: p.lambda_for_one_level(near, far), ..p };
                assert!(fitted.lambda <= p.lambda && fitted.lambda >= 0.5 * p.lambda);
                let levels = (level(&fitted, near), level(&fitted, far));
                if levels.1 < p.num_levels {
                    assert_eq!(levels.0, levels.1, "near {near} far {far}");
                    assert!(levels.1 <= level(&p, near), "near {near} far {far}");
                }
            }
        }
    }

    #[test]
    fn a_large_object_keeps_the_rule() {
        let p = MapParams::default();
        // Spread over more than a factor √2 in range (the teddy: 0.8–1.28 m).
        assert_eq!(p.lambda_for_one_level(0.8, 1.28), p.lambda);
        for (near, far) in [(0.0, 0.5), (1.0, f64::INFINITY), (f64::NAN, 1.0), (1.2, 1.0)] {
            assert_eq!(p.lambda_for_one_level(near, far), p.lambda, "{near} {far}");
        }
    }
}
