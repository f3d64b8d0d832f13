//! Building a map from one RGB-D image (paper §3.3, §3.4).

use super::SurfelMap;
use super::aggregate::{AggregationInput, BAND_ROWS, Band, MEASURED_DEPTHS, Placement};
use super::assemble::Assembly;
use super::border::{BorderScratch, mark_borders};
use super::jobs::ItemJobs;
use super::params::{MAX_LEVELS, MapParams};
use super::region::{ImageRegion, raw_depth_interval};
use crate::frame::{FrameError, RayTable, RgbdFrame};
use crate::geometry::{CameraError, Pose};
use nalgebra::Vector3;
use rayon::prelude::*;
use std::ops::Range;
use thiserror::Error;

/// Why a map could not be built from a frame.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MapError {
    /// Fusion kept no point (an empty volume of interest).
    #[error("no point of any view lies inside the volume of interest")]
    NothingInside,
    /// The frame itself is invalid.
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// The camera cannot be used (e.g. distortion that does not invert).
    #[error("camera: {0}")]
    Camera(#[from] CameraError),
    /// The frame is larger than the builder was sized for.
    #[error("frame {width}x{height} exceeds the builder's maximum {max_width}x{max_height}")]
    FrameTooLarge {
        /// Frame width.
        width: usize,
        /// Frame height.
        height: usize,
        /// Largest width the builder accepts.
        max_width: usize,
        /// Largest height the builder accepts.
        max_height: usize,
    },
}

/// What went into a map, and what did not fit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BuildReport {
    /// Image aggregates inserted (§3.3).
    pub aggregates: usize,
    /// Octree nodes.
    pub nodes: usize,
    /// Surfels (all, including those with too few points).
    pub surfels: usize,
    /// Surfels usable for registration.
    pub usable_surfels: usize,
    /// Points dropped because an aggregation band was full.
    pub dropped_points: u64,
    /// Aggregates dropped because the node arena was full.
    pub dropped_aggregates: usize,
    /// Surfels not created because the surfel arena was full.
    pub dropped_surfels: usize,
}

impl BuildReport {
    /// Whether anything was dropped for lack of capacity.
    pub fn is_complete(&self) -> bool {
        self.dropped_points == 0 && self.dropped_aggregates == 0 && self.dropped_surfels == 0
    }
}

/// A frame placed in the map's frame, for fusion (§5.1.3).
#[derive(Debug, Clone, Copy)]
pub struct PlacedFrame<'a> {
    /// The frame.
    pub frame: &'a RgbdFrame<'a>,
    /// Where its camera is in the map's frame.
    pub map_from_camera: Pose,
}

/// Builds maps from RGB-D frames; owns every scratch buffer, allocated once.
#[derive(Debug)]
pub struct MapBuilder {
    max_width: usize,
    max_height: usize,
    rays: RayTable,
    flags: Vec<u8>,
    borders: BorderScratch,
    bands: Vec<Band>,
    active_bands: usize,
    assembly: Assembly,
}

impl MapBuilder {
    /// A builder for frames up to `max_width × max_height` and maps of up to
    /// `surfel_capacity` surfels.
    pub fn new(max_width: usize, max_height: usize, surfel_capacity: usize) -> Self {
        let pixels = max_width * max_height;
        let bands: Vec<Band> = (0..max_height.div_ceil(BAND_ROWS))
            .map(|b| Band::new(b * BAND_ROWS..((b + 1) * BAND_ROWS).min(max_height), max_width))
            .collect();
        let aggregate_capacity = bands.iter().map(|b| b.aggregates.capacity()).sum();
        MapBuilder {
            max_width,
            max_height,
            rays: RayTable::with_capacity(pixels),
            flags: vec![0; pixels],
            borders: BorderScratch::new(max_width, max_height),
            bands,
            active_bands: 0,
            assembly: Assembly::with_capacity(aggregate_capacity, surfel_capacity),
        }
    }

    /// Takes a ray table prepared elsewhere (at start-up, beside other work): frames of
    /// its camera then use it as it is. (A frame of another camera recomputes it as
    /// always; one larger than the table's image allocates.)
    pub fn adopt_rays(&mut self, rays: RayTable) {
        self.rays = rays;
    }

    /// Builds `map` from `frame`, replacing its content. Allocates nothing once the
    /// builder has seen a frame of this camera.
    pub fn build(&mut self, frame: &RgbdFrame, map: &mut SurfelMap) -> Result<BuildReport, MapError> {
        let region = ImageRegion::whole(frame.width(), frame.height());
        self.build_region(frame, &region, map)
    }

    /// Builds `map` from the pixels of `region` only (paper §5.2: the tracker's scene map
    /// covers the volume of interest around the object). The region's edges count as
    /// image borders (§3.4). Allocates nothing once the builder has seen a frame of this
    /// camera.
    pub fn build_region(
        &mut self,
        frame: &RgbdFrame,
        region: &ImageRegion,
        map: &mut SurfelMap,
    ) -> Result<BuildReport, MapError> {
        self.aggregate(frame, &map.params, None, region)?;
        let bands = &self.bands[..self.active_bands];
        let dropped = self.assembly.assemble(bands, map);
        Ok(report(bands, map, dropped))
    }

    /// Fuses several frames, each at its pose, into one map (§5.1.3), keeping only
    /// the points `keep` accepts (a volume of interest, in the map frame). Pixels on
    /// virtual borders are left out: their cells are seen only in part, and other views
    /// see them whole. The statistics of all views are merged (Eq. 1). Allocates as
    /// much as the views need (for mapping, not for the tracker loop).
    pub fn fuse(
        &mut self,
        views: &[PlacedFrame],
        keep: &(dyn Fn(&Vector3<f32>) -> bool + Sync),
        map: &mut SurfelMap,
    ) -> Result<BuildReport, MapError> {
        let mut fused: Vec<Band> = Vec::new();
        for view in views {
            let r = view.map_from_camera.rotation.to_rotation_matrix().into_inner().cast::<f32>();
            let t = view.map_from_camera.translation.vector.cast::<f32>();
            let placement = Placement { rotation: r, translation: t, keep };
            let whole = ImageRegion::whole(view.frame.width(), view.frame.height());
            self.aggregate(view.frame, &map.params, Some(placement), &whole)?;
            fused.extend(self.bands[..self.active_bands].iter().filter(|b| !b.aggregates.is_empty()).cloned());
        }
        if fused.is_empty() {
            return Err(MapError::NothingInside);
        }
        let dropped = self.assembly.assemble(&fused, map);
        Ok(report(&fused, map, dropped))
    }

    /// Borders (§3.4) and image aggregation (§3.3) of one frame into the bands.
    fn aggregate(
        &mut self,
        frame: &RgbdFrame,
        params: &MapParams,
        placement: Option<Placement>,
        region: &ImageRegion,
    ) -> Result<(), MapError> {
        let (width, height) = (frame.width(), frame.height());
        if width > self.max_width || height > self.max_height {
            return Err(MapError::FrameTooLarge {
                width,
                height,
                max_width: self.max_width,
                max_height: self.max_height,
            });
        }
        self.rays.ensure(&frame.camera)?;
        let ((rows, cols), (point_rows, point_cols)) = region.clipped(width, height);
        self.configure_bands(width, rows.clone(), &point_rows);
        let flags = &mut self.flags[..width * height];
        mark_borders(
            frame.depth,
            self.rays.range2_factors(),
            width,
            (rows, cols.clone()),
            flags,
            params,
            &mut self.borders,
        );
        let flags = &*flags;
        let mut inv_resolution = [0.0f32; MAX_LEVELS];
        for (l, inv) in inv_resolution.iter_mut().enumerate().take(params.num_levels) {
            *inv = (1.0 / params.resolution(l)) as f32;
        }
        let input = AggregationInput {
            frame,
            rays: self.rays.rays(),
            flags,
            level_thresholds_r2: params.level_thresholds_r2(),
            inv_resolution,
            num_levels: params.num_levels,
            smooth_view_dirs: params.smooth_view_dirs,
            color_scatter: params.color_scatter,
            placement,
            cols: point_cols,
            gate: region.gate.as_ref(),
            gate_depth_raw: region.gate.as_ref().map_or(MEASURED_DEPTHS, |g| {
                raw_depth_interval(g.camera_depth_range(), frame.camera.depth_scale_m as f32)
            }),
            spans: region.spans.as_ref(),
        };
        self.bands[..self.active_bands].par_iter_mut().item_jobs().for_each(|b| b.aggregate(&input));
        Ok(())
    }

    /// Cuts `rows` into bands of `BAND_ROWS` from its first row, each aggregating its
    /// rows within `point_rows` (the others give no points). Band `b` was sized for
    /// rows `b·BAND_ROWS..` of the largest image, and gets no more rows than that.
    fn configure_bands(&mut self, width: usize, rows: Range<usize>, point_rows: &Range<usize>) {
        self.active_bands = rows.len().div_ceil(BAND_ROWS);
        for (b, band) in self.bands.iter_mut().enumerate().take(self.active_bands) {
            let start = rows.start + b * BAND_ROWS;
            let end = (start + BAND_ROWS).min(rows.end);
            let first = start.max(point_rows.start);
            band.configure(first..end.min(point_rows.end).max(first), width);
        }
    }
}

fn report(bands: &[Band], map: &SurfelMap, dropped: super::assemble::Dropped) -> BuildReport {
    BuildReport {
        aggregates: bands.iter().map(|b| b.aggregates.len()).sum(),
        nodes: map.tree.nodes.len(),
        surfels: map.surfels.len(),
        usable_surfels: map.surfels.iter().filter(|s| s.usable()).count(),
        dropped_points: bands.iter().map(|b| b.dropped_points as u64).sum(),
        dropped_aggregates: dropped.aggregates,
        dropped_surfels: dropped.surfels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{CameraModel, PinholeIntrinsics};
    use crate::map::{MapCapacity, NONE};

    /// A pinhole camera of `width × height` (QVGA-like intrinsics, scaled).
    fn camera(width: u32, height: u32) -> CameraModel {
        let s = width as f64 / 320.0;
        CameraModel {
            width,
            height,
            intrinsics: PinholeIntrinsics { fx: 268.0 * s, fy: 270.0 * s, cx: 160.0 * s, cy: 124.0 * s },
            distortion: crate::geometry::NO_DISTORTION,
            depth_scale_m: 0.0002,
        }
    }

    /// A slanted wall with a colour ramp: neighbouring rows share cells.
    fn wall(camera: &CameraModel) -> (Vec<u8>, Vec<u16>) {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let depth = (0..w * h).map(|i| 15000 + (i % w) as u16 * 8).collect();
        let rgb = (0..w * h).flat_map(|i| [(i % w / 3) as u8, 90, (i / w / 2) as u8]).collect();
        (rgb, depth)
    }

    fn region(
        rows: Range<usize>,
        cols: Range<usize>,
        point_rows: Range<usize>,
        point_cols: Range<usize>,
    ) -> ImageRegion {
        ImageRegion { rows, cols, point_rows, point_cols, gate: None, spans: None }
    }

    #[test]
    fn a_region_map_depends_neither_on_earlier_frames_nor_on_the_margin_s_points() {
        let camera = camera(320, 240);
        let (rgb, depth) = wall(&camera);
        let frame = RgbdFrame::new(0, camera, &rgb, &depth).expect("consistent frame");
        let capacity = MapCapacity::for_image(320 * 240);
        let new_map = || SurfelMap::new(MapParams::default(), capacity).expect("valid parameters");
        // Everything per surfel, its statistics, view direction, descriptor, normal and
        // neighbourhoods included: the scratch a builder (and a map) reuses must not carry
        // anything over from earlier frames.
        let surfels = |map: &SurfelMap| {
            let per_surfel = map.surfels().iter().zip(map.descriptors()).zip(map.normals()).enumerate();
            let rows = |i: usize, s: &crate::map::Surfel| (*map.surfel_neighbors(i as u32), *map.neighbors(s.node));
            let stats = |s: &crate::map::Surfel| (s.count, s.mean, s.cov_packed, s.color);
            per_surfel
                .map(|(i, ((s, d), n))| (s.node, s.dir, stats(s), s.valid, map.view_dirs[i], *d, *n, rows(i, s)))
                .collect::<Vec<_>>()
        };
        // A builder that has seen other regions of the frame before…
        let mut used = MapBuilder::new(320, 240, capacity.surfels);
        let mut map = new_map();
        used.build(&frame, &mut map).expect("builds");
        used.build_region(&frame, &region(40..200, 30..300, 40..200, 30..300), &mut map).expect("builds");
        used.build_region(&frame, &region(40..200, 60..250, 40..200, 60..250), &mut map).expect("builds");
        // …builds the same map as a fresh one.
        let mut fresh = MapBuilder::new(320, 240, capacity.surfels);
        let mut expected = new_map();
        fresh.build_region(&frame, &region(40..200, 60..250, 40..200, 60..250), &mut expected).expect("builds");
        assert!(!expected.surfels().is_empty());
        assert_eq!(surfels(&map), surfels(&expected));
        // The neighbourhood tables, whose rows a rebuild overwrites without clearing, hold
        // their definitions: the nodes of the 26 neighbouring cells, and their surfels of
        // the same view direction.
        for (i, node) in map.nodes().iter().enumerate() {
            for (k, o) in crate::map::tree::NEIGHBOR_OFFSETS.iter().enumerate() {
                let key = [node.key[0] + o[0], node.key[1] + o[1], node.key[2] + o[2]];
                let nb = map.neighbors(i as u32)[k];
                assert_eq!(Some(nb).filter(|&n| n != NONE), map.find(node.level as usize, key), "node {i}");
            }
        }
        for (i, s) in map.surfels().iter().enumerate() {
            let expected = map
                .neighbors(s.node)
                .map(|n| if n == NONE { NONE } else { map.nodes()[n as usize].surfels[s.dir as usize] });
            assert_eq!(*map.surfel_neighbors(i as u32), expected, "surfel {i}");
        }
        // Points come only from the point rows and columns; the margin around them
        // still counts as inside the region for border detection.
        let mut margin = new_map();
        fresh.build_region(&frame, &region(30..210, 50..260, 40..200, 60..250), &mut margin).expect("builds");
        let points = |map: &SurfelMap| map.surfels().iter().filter(|s| s.level == 0).map(|s| s.count).sum::<f32>();
        assert_eq!(points(&margin), points(&expected));
        assert_ne!(surfels(&margin), surfels(&expected), "the region's edges are borders: the margin moves them");
    }

    /// An adopted ray table serves frames of its camera as computed there; a frame of
    /// another camera recomputes it: the map is the one a fresh builder makes.
    #[test]
    fn an_adopted_ray_table_gives_the_same_map() {
        let camera = camera(160, 120);
        let (rgb, depth) = wall(&camera);
        let frame = RgbdFrame::new(0, camera, &rgb, &depth).expect("consistent frame");
        let capacity = MapCapacity::for_image(160 * 120);
        let build = |adopted: Option<&CameraModel>| {
            let mut builder = MapBuilder::new(160, 120, capacity.surfels);
            if let Some(c) = adopted {
                let mut rays = RayTable::with_capacity(160 * 120);
                rays.ensure(c).expect("a valid camera");
                builder.adopt_rays(rays);
            }
            let mut map = SurfelMap::new(MapParams::default(), capacity).expect("valid parameters");
            builder.build(&frame, &mut map).expect("builds");
            map.surfels().iter().map(|s| (s.node, s.dir, s.mean, s.count)).collect::<Vec<_>>()
        };
        let fresh = build(None);
        assert!(!fresh.is_empty());
        assert_eq!(build(Some(&camera)), fresh);
        let other = CameraModel { intrinsics: PinholeIntrinsics { fx: 150.0, ..camera.intrinsics }, ..camera };
        assert_eq!(build(Some(&other)), fresh);
    }

    #[test]
    fn the_contour_levels_are_those_of_the_nodes_flags() {
        let camera = camera(160, 120);
        let (rgb, mut depth) = wall(&camera);
        // A box 0.8 m in front of the wall: its outline is a foreground contour (§3.4).
        for (i, d) in depth.iter_mut().enumerate() {
            if (30..90).contains(&(i / 160)) && (40..120).contains(&(i % 160)) {
                *d -= 4000;
            }
        }
        let frame = RgbdFrame::new(0, camera, &rgb, &depth).expect("consistent frame");
        let capacity = MapCapacity::for_image(160 * 120);
        let mut map = SurfelMap::new(MapParams::default(), capacity).expect("valid parameters");
        let mut builder = MapBuilder::new(160, 120, capacity.surfels);
        let scanned = |map: &SurfelMap| crate::map::tree::scan_contour_levels(map.nodes());
        builder.build(&frame, &mut map).expect("builds");
        assert_ne!(map.contour_levels(), 0, "the box's outline");
        assert_eq!(map.contour_levels(), scanned(&map));
        let restored = SurfelMap::restore(map.parts()).expect("consistent parts");
        assert_eq!(restored.contour_levels(), scanned(&map));
        // The same map rebuilt from the wall alone keeps none of them.
        builder.build_region(&frame, &region(95..120, 0..160, 95..120, 0..160), &mut map).expect("builds");
        assert!(!map.surfels().is_empty());
        assert_eq!(map.contour_levels(), scanned(&map));
        assert_eq!(map.contour_levels(), 0);
    }

    #[test]
    fn finding_a_cell_near_a_node_gives_the_node_found_by_descent() {
        let camera = camera(160, 120);
        let (rgb, depth) = wall(&camera);
        let frame = RgbdFrame::new(0, camera, &rgb, &depth).expect("consistent frame");
        let capacity = MapCapacity::for_image(160 * 120);
        let mut map = SurfelMap::new(MapParams::default(), capacity).expect("valid parameters");
        MapBuilder::new(160, 120, capacity.surfels).build(&frame, &mut map).expect("builds");
        let (mut near, mut far) = (0, 0);
        for (i, node) in map.nodes().iter().enumerate() {
            let level = node.level as usize;
            // Every cell within three cells of the node, present or not.
            for dx in -3..=3 {
                for dy in -3..=3 {
                    for dz in -3..=3 {
                        let key = [node.key[0] + dx, node.key[1] + dy, node.key[2] + dz];
                        let found = map.find_near(level, key, i as u32);
                        assert_eq!(found, map.find(level, key), "node {i}, offset ({dx}, {dy}, {dz})");
                        let within = dx.abs() <= 1 && dy.abs() <= 1 && dz.abs() <= 1;
                        (near, far) = if within { (near + found.is_some() as usize, far) } else { (near, far + 1) };
                    }
                }
            }
            // A node of another level is no neighbour: found by descent.
            if level > 0 {
                assert_eq!(map.find_near(level - 1, node.key, i as u32), map.find(level - 1, node.key));
            }
        }
        assert!(near > map.nodes().len() && far > 0, "{near} cells found through neighbour tables");
    }
}
