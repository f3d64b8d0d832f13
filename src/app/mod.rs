//! The command-line jobs: they read files, time work, show progress and print reports.
//! The only place besides `main.rs` that talks to the user.

pub mod bench;
pub mod dataset;
pub mod mapper;
pub mod model_cmd;
pub mod odometry;
pub mod render;
pub mod report;
