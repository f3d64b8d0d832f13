//! Parameters of map building (paper §3) and the capacities of its arenas.

use thiserror::Error;

/// The most resolution levels a map can have.
pub const MAX_LEVELS: usize = 8;

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
    /// this off: each pixel then adds to 13 sums instead of 28 (docs/benchmarks.md, stop
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
