//! Pose-graph optimisation over key views (paper §5.1.2).
//!
//! Vertices are key-view poses `Xᵥ = world_from_keyview`; an edge `(i, j, Z, Ω)` says
//! `Xᵢ⁻¹ Xⱼ ≈ Z` with information `Ω`. Its residual is the left-increment log of the
//! error, `r = log(Xᵢ⁻¹ Xⱼ Z⁻¹)`: when the registration that produced `Z` reports the
//! covariance `Σ` of a left perturbation of `Z`, `Xᵢ⁻¹Xⱼ = ΔT(n)·Z` with `n ~ N(0, Σ)`
//! and `r = n`, so `Ω = Σ⁻¹` is used as is.
//!
//! Variables are left increments `Xᵥ ← ΔT(δᵥ) Xᵥ` (conventions in `geometry::se3`);
//! vertex 0 is held fixed (the gauge). With `E = Xᵢ⁻¹XⱼZ⁻¹` and `η = Ad(Xᵢ⁻¹)(δⱼ − δᵢ)`,
//! `E(δ) ≈ ΔT(η)·E`, so `∂r/∂δⱼ = D·Ad(Xᵢ⁻¹) = −∂r/∂δᵢ` with
//! `D = [[I, −[t_E]×], [0, J_l⁻¹(ω_E)]]` (`J_l` the left Jacobian of SO(3)).
//! Levenberg–Marquardt steps solve the sparse normal equations by faer's sparse
//! Cholesky (AMD ordering).

use crate::geometry::Pose;
use crate::geometry::se3::{compose_left, left_adjoint, left_log, skew};
use faer::Side;
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMat, Triplet};
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use thiserror::Error;

/// Why an optimisation step could not be taken.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum GraphError {
    /// The normal equations are not positive definite (a vertex not connected to the
    /// fixed one, or a degenerate information matrix).
    #[error("the pose graph is not well constrained (a key view without a path to the first, or a singular edge)")]
    NotPositiveDefinite,
    /// An edge names a vertex that does not exist.
    #[error("edge {edge} refers to vertex {vertex}, but the graph has {vertices} vertices")]
    BadEdge {
        /// Edge index.
        edge: usize,
        /// The vertex it names.
        vertex: usize,
        /// Vertices in the graph.
        vertices: usize,
    },
}

/// What an edge came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EdgeKind {
    /// Tracking registered a new key view to its reference.
    KeyView,
    /// A validated extra registration between existing key views (loop closure).
    LoopClosure,
}

/// A relative-pose constraint between two key views.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    /// Vertex `i`.
    pub from: usize,
    /// Vertex `j`.
    pub to: usize,
    /// Measured `Xᵢ⁻¹ Xⱼ`.
    pub measurement: Pose,
    /// Information matrix of the left perturbation of the measurement.
    pub information: Matrix6<f64>,
    /// Origin of the edge.
    pub kind: EdgeKind,
}

/// One LM step's outcome.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// χ² before the step.
    pub chi2_before: f64,
    /// χ² after (equal to before if the step was rejected).
    pub chi2_after: f64,
    /// Largest vertex increment (translation m, rotation rad combined).
    pub max_step: f64,
    /// The step lowered χ² and was kept.
    pub accepted: bool,
}

/// A pose graph with a Levenberg–Marquardt optimiser.
#[derive(Debug, Clone, Default)]
pub struct PoseGraph {
    /// Vertex poses (`world_from_keyview`).
    pub vertices: Vec<Pose>,
    /// Constraints.
    pub edges: Vec<Edge>,
    lambda: f64,
    /// The symbolic factorisation (fill-reducing ordering, elimination tree) of the
    /// normal equations, reused while the graph's structure — the vertex count and the
    /// edge endpoints — is unchanged.
    symbolic: Option<CachedSymbolic>,
}

/// A symbolic factorisation and the structure it was computed for.
#[derive(Debug, Clone)]
struct CachedSymbolic {
    edges: Vec<(usize, usize)>,
    vertices: usize,
    llt: SymbolicLlt<usize>,
}

/// The inverse of the left Jacobian of SO(3) at `w`.
fn left_jacobian_inverse(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta = w.norm();
    let wx = skew(w);
    if theta < 1e-6 {
        return Matrix3::identity() - 0.5 * wx + wx * wx / 12.0;
    }
    let c = 1.0 / (theta * theta) - (1.0 + theta.cos()) / (2.0 * theta * theta.sin());
    Matrix3::identity() - 0.5 * wx + c * wx * wx
}

/// Residual and Jacobian `∂r/∂δⱼ` (`∂r/∂δᵢ` is its negative) of an edge.
pub(crate) fn edge_residual(xi: &Pose, xj: &Pose, z: &Pose) -> (Vector6<f64>, Matrix6<f64>) {
    let e = xi.inverse() * xj * z.inverse();
    let r = left_log(&e);
    let mut d = Matrix6::identity();
    d.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew(&e.translation.vector)));
    d.fixed_view_mut::<3, 3>(3, 3).copy_from(&left_jacobian_inverse(&Vector3::new(r[3], r[4], r[5])));
    (r, d * left_adjoint(&xi.inverse()))
}

impl PoseGraph {
    /// An empty graph.
    pub fn new() -> Self {
        PoseGraph { vertices: Vec::new(), edges: Vec::new(), lambda: 1e-4, symbolic: None }
    }

    /// Adds a vertex and returns its index.
    pub fn add_vertex(&mut self, pose: Pose) -> usize {
        self.vertices.push(pose);
        self.vertices.len() - 1
    }

    /// Adds an edge.
    pub fn add_edge(&mut self, edge: Edge) -> Result<(), GraphError> {
        for v in [edge.from, edge.to] {
            if v >= self.vertices.len() {
                return Err(GraphError::BadEdge { edge: self.edges.len(), vertex: v, vertices: self.vertices.len() });
            }
        }
        self.edges.push(edge);
        Ok(())
    }

    /// Whether an edge joins `a` and `b` (either way).
    pub fn connected(&self, a: usize, b: usize) -> bool {
        self.edges.iter().any(|e| (e.from == a && e.to == b) || (e.from == b && e.to == a))
    }

    /// `Σ rᵀ Ω r` over all edges.
    pub fn chi2(&self) -> f64 {
        self.chi2_of(&self.vertices)
    }

    fn chi2_of(&self, vertices: &[Pose]) -> f64 {
        self.edges
            .iter()
            .map(|e| {
                let (r, _) = edge_residual(&vertices[e.from], &vertices[e.to], &e.measurement);
                r.dot(&(e.information * r))
            })
            .sum()
    }

    /// One Levenberg–Marquardt step (vertex 0 fixed).
    pub fn step(&mut self) -> Result<StepReport, GraphError> {
        let n = self.vertices.len();
        let chi2_before = self.chi2();
        if n < 2 || self.edges.is_empty() {
            return Ok(StepReport { chi2_before, chi2_after: chi2_before, max_step: 0.0, accepted: false });
        }
        let (triplets, b) = self.normal_equations();
        let dim = 6 * (n - 1);
        for _ in 0..10 {
            let mut damped = triplets.clone();
            for (k, &diag) in self.diagonal(&triplets, dim).iter().enumerate() {
                damped.push(Triplet::new(k, k, self.lambda * diag.max(1e-9)));
            }
            let h = SparseColMat::<usize, f64>::try_new_from_triplets(dim, dim, &damped)
                .map_err(|_| GraphError::NotPositiveDefinite)?;
            let symbolic = self.symbolic_for(&h)?;
            let llt = Llt::try_new_with_symbolic(symbolic, h.as_ref(), Side::Lower)
                .map_err(|_| GraphError::NotPositiveDefinite)?;
            let rhs = faer::Mat::<f64>::from_fn(dim, 1, |i, _| -b[i]);
            let x = llt.solve(&rhs);
            let mut candidate = self.vertices.clone();
            let mut max_step: f64 = 0.0;
            for v in 1..n {
                let delta = Vector6::from_fn(|k, _| x[(6 * (v - 1) + k, 0)]);
                max_step = max_step.max(delta.norm());
                candidate[v] = compose_left(&delta, &self.vertices[v]);
            }
            let chi2_after = self.chi2_of(&candidate);
            // At the optimum a step changes χ² only by rounding: accept it rather than
            // retrying with ever larger damping.
            if chi2_after.is_finite() && chi2_after <= chi2_before * (1.0 + 1e-12) {
                self.vertices = candidate;
                self.lambda = (self.lambda / 3.0).max(1e-9);
                return Ok(StepReport { chi2_before, chi2_after, max_step, accepted: true });
            }
            self.lambda *= 4.0;
            if max_step < 1e-12 {
                break;
            }
        }
        Ok(StepReport { chi2_before, chi2_after: chi2_before, max_step: 0.0, accepted: false })
    }

    /// The cached symbolic factorisation if the structure is unchanged, else a new one.
    fn symbolic_for(&mut self, h: &SparseColMat<usize, f64>) -> Result<SymbolicLlt<usize>, GraphError> {
        let same = self.symbolic.as_ref().is_some_and(|c| {
            c.vertices == self.vertices.len()
                && c.edges.len() == self.edges.len()
                && c.edges.iter().zip(&self.edges).all(|(&(a, b), e)| (a, b) == (e.from, e.to))
        });
        if !same {
            let symbolic =
                SymbolicLlt::try_new(h.symbolic(), Side::Lower).map_err(|_| GraphError::NotPositiveDefinite)?;
            let edges = self.edges.iter().map(|e| (e.from, e.to)).collect();
            self.symbolic = Some(CachedSymbolic { edges, vertices: self.vertices.len(), llt: symbolic });
        }
        self.symbolic.as_ref().map(|c| c.llt.clone()).ok_or(GraphError::NotPositiveDefinite)
    }

    /// Iterates until a step moves no vertex by more than `tolerance` or `max_steps`.
    pub fn optimize(&mut self, max_steps: usize, tolerance: f64) -> Result<usize, GraphError> {
        for k in 0..max_steps {
            let s = self.step()?;
            if !s.accepted || s.max_step < tolerance {
                return Ok(k + 1);
            }
        }
        Ok(max_steps)
    }

    /// `JᵀΩJ` as triplets (lower triangle) and `JᵀΩr`, over vertices 1.. (0 fixed).
    fn normal_equations(&self) -> (Vec<Triplet<usize, usize, f64>>, Vec<f64>) {
        let n = self.vertices.len();
        let mut b = vec![0.0; 6 * (n - 1)];
        let mut triplets = Vec::with_capacity(self.edges.len() * 4 * 36);
        for e in &self.edges {
            let (r, jj) = edge_residual(&self.vertices[e.from], &self.vertices[e.to], &e.measurement);
            let blocks = [(e.from, -jj), (e.to, jj)];
            for (v, j) in &blocks {
                if *v == 0 {
                    continue;
                }
                let g = j.transpose() * e.information * r;
                for k in 0..6 {
                    b[6 * (v - 1) + k] += g[k];
                }
                // Only the lower triangle: the factorisation reads `Side::Lower`.
                for (w, jw) in &blocks {
                    if *w == 0 || w > v {
                        continue;
                    }
                    let h = j.transpose() * e.information * jw;
                    for r_ in 0..6 {
                        for c in 0..6 {
                            let (row, col) = (6 * (v - 1) + r_, 6 * (w - 1) + c);
                            if row >= col {
                                triplets.push(Triplet::new(row, col, h[(r_, c)]));
                            }
                        }
                    }
                }
            }
        }
        (triplets, b)
    }

    fn diagonal(&self, triplets: &[Triplet<usize, usize, f64>], dim: usize) -> Vec<f64> {
        let mut d = vec![0.0; dim];
        for t in triplets.iter().filter(|t| t.row == t.col) {
            d[t.row] += t.val;
        }
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::se3::left_increment;
    use crate::synthetic::Pcg32;

    fn random_pose(rng: &mut Pcg32, t: f64, r: f64) -> Pose {
        left_increment(&Vector6::from_fn(|k, _| if k < 3 { rng.uniform(-t, t) } else { rng.uniform(-r, r) }))
    }

    #[test]
    fn edge_jacobian_matches_finite_differences() {
        let mut rng = Pcg32::new(1);
        for _ in 0..20 {
            let (xi, xj) = (random_pose(&mut rng, 2.0, 1.0), random_pose(&mut rng, 2.0, 1.0));
            let z = random_pose(&mut rng, 0.05, 0.05) * xi.inverse() * xj;
            let (_, jj) = edge_residual(&xi, &xj, &z);
            let h = 1e-6;
            for k in 0..6 {
                let d = Vector6::from_fn(|i, _| if i == k { h } else { 0.0 });
                let plus = edge_residual(&xi, &compose_left(&d, &xj), &z).0;
                let minus = edge_residual(&xi, &compose_left(&(-d), &xj), &z).0;
                let num_j = (plus - minus) / (2.0 * h);
                assert!((num_j - jj.column(k)).norm() < 1e-6, "∂r/∂δj col {k}: {num_j} vs {}", jj.column(k));
                let plus = edge_residual(&compose_left(&d, &xi), &xj, &z).0;
                let minus = edge_residual(&compose_left(&(-d), &xi), &xj, &z).0;
                let num_i = (plus - minus) / (2.0 * h);
                assert!((num_i + jj.column(k)).norm() < 1e-6, "∂r/∂δi col {k}");
            }
        }
    }

    #[test]
    fn recovers_a_loop_from_noisy_odometry() {
        // A square loop of 12 poses; odometry edges with a bias, one loop closure.
        let mut rng = Pcg32::new(5);
        let truth: Vec<Pose> = (0..12)
            .map(|k| {
                let a = k as f64 / 12.0 * std::f64::consts::TAU;
                left_increment(&Vector6::new(a.cos(), a.sin(), 0.0, 0.0, 0.0, a))
            })
            .collect();
        let mut g = PoseGraph::new();
        let info = Matrix6::identity() * 1e4;
        let mut estimate = truth[0];
        g.add_vertex(estimate);
        for k in 1..12 {
            let z = random_pose(&mut rng, 0.01, 0.01) * truth[k - 1].inverse() * truth[k];
            estimate *= z;
            g.add_vertex(estimate);
            g.add_edge(Edge { from: k - 1, to: k, measurement: z, information: info, kind: EdgeKind::KeyView })
                .unwrap();
        }
        let drift_before = (g.vertices[11].translation.vector - truth[11].translation.vector).norm();
        let z = truth[11].inverse() * truth[0];
        g.add_edge(Edge { from: 11, to: 0, measurement: z, information: info * 10.0, kind: EdgeKind::LoopClosure })
            .unwrap();
        let chi2 = g.chi2();
        let steps = g.optimize(50, 1e-9).unwrap();
        let drift_after = (g.vertices[11].translation.vector - truth[11].translation.vector).norm();
        assert!(g.chi2() < chi2 * 0.1, "χ² {chi2} → {}", g.chi2());
        assert!(drift_after < 0.5 * drift_before, "{drift_before} → {drift_after} in {steps} steps");
    }
}
