//! The arguments of the clients of a running tracker (`poses`, `detect`).

use super::args::{at_least_one, service_name};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct PosesArgs {
    /// The pose service (the tracker config's poses.service).
    #[arg(long, default_value = mrsmap::io::ipc::POSES_SERVICE, value_parser = service_name)]
    pub service: String,
    /// Write each object's object_from_camera as a TUM trajectory (frames whose pose was
    /// estimated from them; a comment line for the others: lost, initialising, invalid,
    /// or held, the last good pose kept through a failed registration). Written as the poses arrive, into OUT.partial,
    /// which takes the name OUT when the client stops: a client that is killed leaves
    /// OUT.partial with every pose it received.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace the OUT.partial trajectories that a client stopped before its end left
    /// (without it they are an error: they hold that run's poses).
    #[arg(long, requires = "out")]
    pub force: bool,
    /// Stop after this many pose messages.
    #[arg(long, value_parser = at_least_one::<u64>)]
    pub count: Option<u64>,
    /// Stop after this many seconds without a pose.
    #[arg(long)]
    pub timeout: Option<f64>,
    /// Print only the summary, not every pose.
    #[arg(long, conflicts_with = "json")]
    pub quiet: bool,
    /// Print every pose as one JSON object per line (JSON Lines) on stdout, with every
    /// field of the message plus object_from_camera and the latency, and the summary on
    /// stderr: for a program that reads poses without iceoryx2, e.g. `mrsmap poses --json
    /// | python3 log.py`. Stdout is flushed at every line.
    #[arg(long)]
    pub json: bool,
}

#[derive(Args)]
pub struct DetectArgs {
    /// The object's name in the tracker config.
    #[arg(long)]
    pub object: String,
    /// The detected pose, camera_from_object: tx ty tz (metres) qx qy qz qw, in the
    /// camera's optical frame (REP 103: x right, y down, z forward).
    #[arg(long, num_args = 7, allow_negative_numbers = true, required = true,
          value_names = ["TX", "TY", "TZ", "QX", "QY", "QZ", "QW"])]
    pub pose: Vec<f64>,
    /// Capture stamp (ns since the Unix epoch) of the frame the object was detected in:
    /// the tracker ignores a detection older than its detections.max_age_s [default: no
    /// stamp, applied to the next frame whatever its age].
    #[arg(long)]
    pub frame_stamp_ns: Option<u64>,
    /// Re-initialise the object even while it is being tracked [default: only when it is
    /// lost or initialising].
    #[arg(long)]
    pub always: bool,
    /// The detection service (the tracker config's detections.service).
    #[arg(long, default_value = mrsmap::io::ipc::DETECTIONS_SERVICE, value_parser = service_name)]
    pub service: String,
    /// The pose service (the tracker config's poses.service).
    #[arg(long, default_value = mrsmap::io::ipc::POSES_SERVICE, value_parser = service_name)]
    pub poses: String,
    /// Seconds to wait for the tracker to track a frame after the detection.
    #[arg(long, default_value_t = 5.0)]
    pub timeout: f64,
}
