//! Key-view SLAM (paper §5.1): tracking against a reference key view, key-view creation,
//! randomised loop closure (§5.1.1) and pose-graph optimisation (§5.1.2).
//!
//! A frame goes through [`Slam::build`], [`Slam::track`], [`Slam::update_key_views`],
//! [`Slam::close_loop`] and [`Slam::optimize_step`] in this order ([`Slam::process`]
//! does all five); the stages are separate so that a caller can time them. Memory is
//! allocated here as the map grows (key views are kept); this module is for mapping, not
//! for the tracker loop.

use super::graph::{Edge, EdgeKind, GraphError, PoseGraph};
use super::params::SlamParams;
use crate::frame::RgbdFrame;
use crate::geometry::se3::pose_distance;
use crate::geometry::{CameraModel, Pose};
use crate::map::{BuildReport, MapBuilder, MapCapacity, MapError, MapParamsError, SurfelMap};
use crate::registration::match_score;
use crate::registration::{RegistrationError, RegistrationWorkspace, register};
use crate::synthetic::Pcg32;
use nalgebra::Matrix6;

/// A key view: its map, its images (for fusion) and its validation reference.
#[derive(Debug, Clone)]
pub struct KeyView {
    /// Depth timestamp of the frame (ns).
    pub stamp_ns: u64,
    /// The key view's map (camera frame).
    pub map: SurfelMap,
    /// The frame's camera.
    pub camera: CameraModel,
    /// RGB8 pixels.
    pub rgb: Vec<u8>,
    /// Depth pixels.
    pub depth: Vec<u16>,
    /// Matching score of the key view under its first constraint: the yardstick for
    /// validating later constraints (§5.1.1).
    pub initial_score: Option<f64>,
}

/// What tracking did with a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrackStatus {
    /// The very first frame: it became key view 0.
    First,
    /// Registered to the reference key view.
    Tracked,
    /// Registration failed: the pose is held at the last estimate.
    Lost(RegistrationError),
}

/// The outcome of one randomised loop-closure attempt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LoopOutcome {
    /// No key view qualified as a candidate.
    NoCandidate,
    /// The constraint between the reference and `other` passed validation.
    Accepted {
        /// The other key view.
        other: usize,
    },
    /// The registration failed.
    RegistrationFailed {
        /// The other key view.
        other: usize,
        /// Why.
        error: RegistrationError,
    },
    /// The registration succeeded but the matching likelihood was too low.
    Rejected {
        /// The other key view.
        other: usize,
        /// Score of the other key view under the new constraint, as a fraction of its
        /// initial score.
        fraction_other: f64,
        /// Likewise for the reference.
        fraction_reference: f64,
    },
}

/// Per-frame record, to re-express the trajectory with the final key-view poses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameRecord {
    /// Depth timestamp (ns).
    pub stamp_ns: u64,
    /// The reference key view.
    pub reference: usize,
    /// Pose of the camera in the reference key view.
    pub reference_from_camera: Pose,
    /// Tracking status.
    pub status: TrackStatus,
}

/// Counters for the summary.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SlamCounters {
    /// Frames processed.
    pub frames: usize,
    /// Frames whose tracking failed.
    pub lost: usize,
    /// Loop-closure attempts.
    pub loop_attempts: usize,
    /// Loop closures accepted.
    pub loops_accepted: usize,
    /// Loop closures rejected by the matching likelihood.
    pub loops_rejected: usize,
    /// Loop-closure registrations that failed.
    pub loops_failed: usize,
    /// Graph steps that failed (left the graph unchanged).
    pub graph_failures: usize,
}

/// Key-view SLAM over RGB-D frames.
#[derive(Debug)]
pub struct Slam {
    params: SlamParams,
    pub(crate) builder: MapBuilder,
    current: SurfelMap,
    current_report: BuildReport,
    workspace: RegistrationWorkspace,
    /// Key views, indexed like the graph's vertices.
    pub key_views: Vec<KeyView>,
    /// The pose graph over key views.
    pub graph: PoseGraph,
    reference: usize,
    reference_from_camera: Pose,
    /// Camera motion of the last frame (`previous_from_current`), for the prediction.
    velocity: Pose,
    /// Covariance (Eq. 6) of the last successful tracking registration.
    last_covariance: Matrix6<f64>,
    world_from_first: Pose,
    frames: Vec<FrameRecord>,
    rng: Pcg32,
    counters: SlamCounters,
    /// Pairs whose loop constraint was rejected since the last accepted one: retrying
    /// them from the same graph estimate would give the same answer.
    rejected: Vec<(usize, usize)>,
}

/// Why SLAM could not process a frame at all.
#[derive(Debug, thiserror::Error)]
pub enum SlamError {
    /// The frame could not be turned into a map.
    #[error(transparent)]
    Map(#[from] MapError),
    /// The parameters are invalid.
    #[error(transparent)]
    Params(#[from] MapParamsError),
}

impl Slam {
    /// SLAM for frames up to `max_width × max_height`, the first key view at `world_from_first`.
    pub fn new(
        params: SlamParams,
        max_width: usize,
        max_height: usize,
        world_from_first: Pose,
    ) -> Result<Self, SlamError> {
        let capacity = MapCapacity::for_image(max_width * max_height);
        Ok(Slam {
            builder: MapBuilder::new(max_width, max_height, capacity.surfels),
            current: SurfelMap::new(params.map, capacity)?,
            current_report: BuildReport::default(),
            workspace: RegistrationWorkspace::new(capacity.nodes),
            key_views: Vec::new(),
            graph: PoseGraph::new(),
            reference: 0,
            reference_from_camera: Pose::identity(),
            velocity: Pose::identity(),
            last_covariance: Matrix6::identity(),
            world_from_first,
            frames: Vec::new(),
            rng: Pcg32::new(params.seed),
            counters: SlamCounters::default(),
            rejected: Vec::new(),
            params,
        })
    }

    /// All five stages for one frame.
    pub fn process(&mut self, frame: &RgbdFrame) -> Result<(TrackStatus, LoopOutcome), SlamError> {
        self.build(frame)?;
        let status = self.track(frame);
        self.update_key_views(frame);
        let outcome = self.close_loop();
        self.optimize_step();
        Ok((status, outcome))
    }

    /// Stage 1: the map of the frame.
    pub fn build(&mut self, frame: &RgbdFrame) -> Result<BuildReport, SlamError> {
        self.current_report = self.builder.build(frame, &mut self.current)?;
        Ok(self.current_report)
    }

    /// Stage 2: registers the frame to the reference key view, from the constant-velocity
    /// prediction.
    pub fn track(&mut self, frame: &RgbdFrame) -> TrackStatus {
        self.counters.frames += 1;
        if self.key_views.is_empty() {
            self.graph.add_vertex(self.world_from_first);
            self.key_views.push(self.key_view_from(frame));
            self.record(frame.stamp_ns, TrackStatus::First);
            return TrackStatus::First;
        }
        let guess = self.reference_from_camera * self.velocity;
        let reference = &self.key_views[self.reference].map;
        let status = match register(reference, &self.current, &guess, &self.params.registration, &mut self.workspace) {
            Ok(r) => {
                self.velocity = self.reference_from_camera.inverse() * r.model_from_scene;
                self.reference_from_camera = r.model_from_scene;
                self.last_covariance = r.covariance;
                TrackStatus::Tracked
            }
            Err(e) => {
                self.velocity = Pose::identity();
                self.counters.lost += 1;
                TrackStatus::Lost(e)
            }
        };
        self.record(frame.stamp_ns, status);
        status
    }

    fn record(&mut self, stamp_ns: u64, status: TrackStatus) {
        self.frames.push(FrameRecord {
            stamp_ns,
            reference: self.reference,
            reference_from_camera: self.reference_from_camera,
            status,
        });
    }

    fn key_view_from(&self, frame: &RgbdFrame) -> KeyView {
        KeyView {
            stamp_ns: frame.stamp_ns,
            map: self.current.to_compact(),
            camera: frame.camera,
            rgb: frame.rgb.to_vec(),
            depth: frame.depth.to_vec(),
            initial_score: None,
        }
    }

    /// Stage 3: a new key view when the camera has moved far enough from its reference,
    /// else a switch of the reference to the closest key view.
    pub fn update_key_views(&mut self, frame: &RgbdFrame) {
        if !matches!(self.frames.last().map(|f| f.status), Some(TrackStatus::Tracked)) {
            return;
        }
        let (dist, angle) = pose_distance(&Pose::identity(), &self.reference_from_camera);
        let world_from_camera = self.graph.vertices[self.reference] * self.reference_from_camera;
        if dist >= self.params.key_view_distance_m || angle >= self.params.key_view_angle_rad {
            let id = self.graph.add_vertex(world_from_camera);
            let information = information_of(&self.last_covariance);
            let edge = Edge {
                from: self.reference,
                to: id,
                measurement: self.reference_from_camera,
                information,
                kind: EdgeKind::KeyView,
            };
            // The edge names existing vertices: it cannot fail.
            let _ = self.graph.add_edge(edge);
            let mut kv = self.key_view_from(frame);
            let reg = self.params.registration.covariance_regularization;
            let reference = &self.key_views[self.reference];
            kv.initial_score = Some(match_score(&kv.map, &reference.map, &self.reference_from_camera, reg).total);
            if reference.initial_score.is_none() {
                let back = self.reference_from_camera.inverse();
                let score = match_score(&reference.map, &kv.map, &back, reg).total;
                self.key_views[self.reference].initial_score = Some(score);
            }
            self.key_views.push(kv);
            self.reference = id;
            self.reference_from_camera = Pose::identity();
            return;
        }
        // Switch to the closest key view (translation, plus rotation scaled to metres).
        let scale = self.params.key_view_distance_m / self.params.key_view_angle_rad;
        let cost = |k: usize| {
            let (d, a) = pose_distance(&self.graph.vertices[k], &world_from_camera);
            d + scale * a
        };
        let best = (0..self.key_views.len()).min_by(|&a, &b| cost(a).total_cmp(&cost(b))).unwrap_or(self.reference);
        if best != self.reference && cost(best) < cost(self.reference) {
            self.reference_from_camera = self.graph.vertices[best].inverse() * world_from_camera;
            self.reference = best;
        }
    }

    /// Stage 4: one randomised loop-closure attempt (§5.1.1). A key view is drawn with
    /// probability proportional to Eq. (7), `exp(−d²/2σ_d²) · exp(−θ²/2σ_θ²)` of its
    /// distance to the reference in the current graph estimate, among those not yet
    /// connected to the reference and not too far; the registration is validated by the
    /// matching likelihood in both directions against a fraction of each key view's
    /// initial score.
    pub fn close_loop(&mut self) -> LoopOutcome {
        let p = &self.params;
        let r = self.reference;
        let weights: Vec<(usize, f64)> = (0..self.key_views.len())
            .filter(|&k| k != r && !self.graph.connected(r, k) && !self.rejected.contains(&(r.min(k), r.max(k))))
            .filter_map(|k| {
                let (d, a) = pose_distance(&self.graph.vertices[r], &self.graph.vertices[k]);
                (d <= p.loop_max_distance_m && a <= p.loop_max_angle_rad).then(|| {
                    let w = (-d * d / (2.0 * p.loop_sigma_m * p.loop_sigma_m)).exp()
                        * (-a * a / (2.0 * p.loop_sigma_rad * p.loop_sigma_rad)).exp();
                    (k, w)
                })
            })
            .collect();
        let total: f64 = weights.iter().map(|w| w.1).sum();
        if weights.is_empty() || total <= 0.0 {
            return LoopOutcome::NoCandidate;
        }
        let mut pick = self.rng.uniform(0.0, total);
        let mut other = weights[weights.len() - 1].0;
        for &(k, w) in &weights {
            if pick < w {
                other = k;
                break;
            }
            pick -= w;
        }
        self.try_loop(other)
    }

    /// Registers the reference key view with `other` from the graph estimate and adds
    /// the constraint if the matching likelihood validates it in both directions.
    fn try_loop(&mut self, other: usize) -> LoopOutcome {
        let p = &self.params;
        let r = self.reference;
        self.counters.loop_attempts += 1;
        let guess = self.graph.vertices[r].inverse() * self.graph.vertices[other];
        let (reference, candidate) = (&self.key_views[r], &self.key_views[other]);
        let reg = match register(&reference.map, &candidate.map, &guess, &p.loop_registration, &mut self.workspace) {
            Ok(reg) => reg,
            Err(error) => {
                self.counters.loops_failed += 1;
                self.rejected.push((r.min(other), r.max(other)));
                return LoopOutcome::RegistrationFailed { other, error };
            }
        };
        let t = reg.model_from_scene;
        let regularization = p.registration.covariance_regularization;
        let fraction = |score: f64, initial: Option<f64>| match initial {
            Some(i) if i > 0.0 => score / i,
            _ => 0.0,
        };
        let fraction_other =
            fraction(match_score(&candidate.map, &reference.map, &t, regularization).total, candidate.initial_score);
        let fraction_reference = fraction(
            match_score(&reference.map, &candidate.map, &t.inverse(), regularization).total,
            reference.initial_score,
        );
        if fraction_other < p.loop_accept_fraction || fraction_reference < p.loop_accept_fraction {
            self.counters.loops_rejected += 1;
            self.rejected.push((r.min(other), r.max(other)));
            return LoopOutcome::Rejected { other, fraction_other, fraction_reference };
        }
        let edge = Edge {
            from: r,
            to: other,
            measurement: t,
            information: information_of(&reg.covariance),
            kind: EdgeKind::LoopClosure,
        };
        let _ = self.graph.add_edge(edge);
        self.counters.loops_accepted += 1;
        self.rejected.clear();
        LoopOutcome::Accepted { other }
    }

    /// Stage 5: one pose-graph step (§5.1.2).
    pub fn optimize_step(&mut self) -> Option<GraphError> {
        if self.graph.vertices.len() < 2 {
            return None;
        }
        match self.graph.step() {
            Ok(_) => None,
            Err(e) => {
                self.counters.graph_failures += 1;
                Some(e)
            }
        }
    }

    /// Ends a sequence: tries every close key-view pair not yet connected (the
    /// random draw may not have reached them), re-registers every edge from the current
    /// graph estimate (its first registration started from a worse guess), and
    /// optimises the graph to convergence. Returns the optimisation steps.
    pub fn finish(&mut self) -> Result<usize, GraphError> {
        self.graph.optimize(100, 1e-7)?;
        let p = self.params;
        let n = self.key_views.len();
        for i in 0..n {
            for j in i + 1..n {
                let (d, a) = pose_distance(&self.graph.vertices[i], &self.graph.vertices[j]);
                if self.graph.connected(i, j) || d > p.loop_max_distance_m || a > p.loop_max_angle_rad {
                    continue;
                }
                self.reference = i;
                self.rejected.retain(|&(a, b)| (a, b) != (i, j));
                let _ = self.try_loop(j);
            }
        }
        self.graph.optimize(100, 1e-7)?;
        self.refine_edges();
        self.graph.optimize(100, 1e-7)
    }

    /// Re-registers every edge from the current graph estimate; keeps the new
    /// measurement where the registration succeeds.
    fn refine_edges(&mut self) {
        for e in 0..self.graph.edges.len() {
            let edge = self.graph.edges[e];
            let guess = self.graph.vertices[edge.from].inverse() * self.graph.vertices[edge.to];
            let (a, b) = (&self.key_views[edge.from].map, &self.key_views[edge.to].map);
            if let Ok(r) = register(a, b, &guess, &self.params.loop_registration, &mut self.workspace) {
                self.graph.edges[e].measurement = r.model_from_scene;
                self.graph.edges[e].information = information_of(&r.covariance);
            }
        }
    }

    /// Every frame's pose in the world, with the current key-view poses.
    pub fn trajectory(&self) -> Vec<(u64, Pose, TrackStatus)> {
        self.frames
            .iter()
            .map(|f| (f.stamp_ns, self.graph.vertices[f.reference] * f.reference_from_camera, f.status))
            .collect()
    }

    /// Re-expresses the map in another world frame: every key-view pose becomes
    /// `new_from_old · pose` (relative poses, edges and the trajectory's shape are
    /// unchanged).
    pub fn change_world(&mut self, new_from_old: &Pose) {
        for v in &mut self.graph.vertices {
            *v = new_from_old * *v;
        }
        self.world_from_first = new_from_old * self.world_from_first;
    }

    /// The counters.
    pub fn counters(&self) -> SlamCounters {
        self.counters
    }

    /// The parameters.
    pub fn params(&self) -> &SlamParams {
        &self.params
    }
}

/// `Σ⁻¹`, symmetrised; a tiny ridge keeps it positive definite.
fn information_of(cov: &Matrix6<f64>) -> Matrix6<f64> {
    let c = (cov + cov.transpose()) * 0.5;
    let ridge = c.diagonal().max() * 1e-9;
    let inv = (c + Matrix6::identity() * ridge).try_inverse().unwrap_or_else(Matrix6::identity);
    (inv + inv.transpose()) * 0.5
}
