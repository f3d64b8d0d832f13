//! # mrsmap — multi-resolution surfel maps for RGB-D registration and tracking
//!
//! A Rust implementation of Stückler & Behnke, *Multi-Resolution Surfel Maps for
//! Efficient Dense 3D Modeling and Tracking* (JVCI 2014).
//!
//! Data flow, one module per step (each may only use the ones to its left):
//!
//! ```text
//! geometry ← frame ← map ← registration ← odometry    (core: no I/O, clocks, logging)
//! eval (trajectory metrics)   synthetic (rendered test scenes)
//! io (TUM files, PNG, camera files) ← app (jobs) ← main.rs (CLI)
//! ```
//!
//! | module | owns | may not touch |
//! |---|---|---|
//! | [`geometry`] | SE(3) poses, tangent conventions, cameras, colour, 3×3 eigen | surfels, files, time, threads |
//! | [`frame`] | borrowed RGB-D frames, per-pixel rays | allocation per frame, where pixels come from |
//! | [`map`] | the surfel octree, image aggregation, borders, descriptors | poses over time, files |
//! | [`registration`] | association, LM on Eq. (5), Newton on Eq. (4), covariance Eq. (6) | maps' construction, config, logging |
//! | [`odometry`] | frame-to-frame pose chaining with a double-buffered map | files, clocks |
//! | [`eval`] | TUM RPE/ATE definitions | files |
//! | [`io`] | TUM datasets, trajectories, PNG, camera files | algorithms |
//! | [`synthetic`] | rasteriser, meshes, seeded procedural scenes (tests, demos) | the core |
//! | [`app`] | the command-line jobs: progress, timing, reports | the maths |
//!
//! Conventions (frames, tangent space, units): `docs/conventions.md`. Paper → code:
//! `docs/algorithm.md`.

#![deny(missing_docs)]

pub mod app;
pub mod eval;
pub mod frame;
pub mod geometry;
pub mod io;
pub mod map;
pub mod model;
pub mod odometry;
pub mod registration;
pub mod slam;
pub mod synthetic;
pub mod tracking;
