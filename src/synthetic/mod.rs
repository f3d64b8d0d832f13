//! Synthetic RGB-D scenes with exact ground truth: a small software rasteriser for
//! coloured triangle meshes, meshes from depth images and OBJ files, and seeded noise.
//!
//! Used by tests, benchmarks and demos; nothing in the core depends on it.

pub mod mesh;
pub mod path;
pub mod raster;
pub mod scene;
pub mod sensor;

pub use mesh::{Mesh, MeshError};
pub use raster::{RenderTarget, clear, draw, render};
pub use scene::{Pcg32, room};
pub use sensor::SensorModel;
