//! # mrsmap — multi-resolution surfel maps for RGB-D registration and tracking
//!
//! A Rust implementation of Stückler & Behnke, *Multi-Resolution Surfel Maps for
//! Efficient Dense 3D Modeling and Tracking* (JVCI 2014).
//!
//! Data flow, one module per step (each may only use the ones to its left):
//!
//! ```text
//! geometry ← frame ← map ← registration ← odometry, slam, tracking   (core: no I/O, clocks, logging)
//! model (files of maps)   eval (trajectory metrics)   synthetic (rendered test scenes)
//! io (TUM files, PNG, configs, wire types, iceoryx2 services) ← app (jobs, processes) ← cli (main.rs)
//! ```
//!
//! | module | owns | may not touch |
//! |---|---|---|
//! | [`geometry`] | SE(3) poses, tangent conventions, cameras, colour, 3×3 eigen | surfels, files, time, threads |
//! | [`frame`] | borrowed RGB-D frames, per-pixel rays | allocation per frame, where pixels come from |
//! | [`map`] | the surfel octree, image aggregation, borders, descriptors | poses over time, files |
//! | [`registration`] | association, LM on Eq. (5), Newton on Eq. (4), covariance Eq. (6) | maps' construction, config, logging |
//! | [`odometry`] | frame-to-frame pose chaining with a double-buffered map | files, clocks |
//! | [`slam`] | key-view SLAM, loop closure, pose graph, fusion into models (§5.1) | files, clocks, the tracker loop |
//! | [`tracking`] | the per-frame object tracking step and its state machine (§5.2) | iceoryx2, files, allocation per frame |
//! | [`model`] | the versioned model file format | algorithms |
//! | [`eval`] | TUM RPE/ATE definitions | files |
//! | [`io`] | TUM datasets, trajectories, PNG, config files, wire types, iceoryx2 services | algorithms |
//! | [`synthetic`] | rasteriser, meshes, seeded procedural scenes (tests, demos) | the core |
//! | [`app`] | the command-line jobs and processes: progress, timing, reports | the maths |
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

#[cfg(test)]
mod test_support;
