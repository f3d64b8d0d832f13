//! The command-line jobs: they read files, time work, show progress and print reports.
//! The only place besides `main.rs` that talks to the user.

pub mod accuracy;
pub mod affinity;
pub mod bench;
pub mod camera_driver;
pub mod capacity;
pub mod convert;
pub mod dataset;
pub mod demo;
pub mod detect_client;
pub mod detections;
pub mod interrupt;
pub mod mapper;
pub mod model_cmd;
pub mod odometry;
pub mod outputs;
pub mod overlay;
pub mod plot;
pub mod pose_files;
pub mod poses_client;
pub mod quality_eval;
pub mod read_ahead;
pub mod recorder;
pub mod render;
pub mod replay;
pub mod replay_detections;
pub mod report;
pub mod synth;
pub mod track_dataset;
pub mod tracker_check;
pub mod tracker_process;
pub mod tracking;
