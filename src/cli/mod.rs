//! The command line: argument definitions, and what each subcommand runs.

mod args;
mod args_live;
mod bench;
mod commands;

use anyhow::Result;
use args::*;
use args_live::*;
use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "mrsmap",
    version,
    about = "Multi-resolution surfel maps: RGB-D map building, registration and odometry",
    long_about = "Multi-resolution surfel maps (Stückler & Behnke, JVCI 2014) for RGB-D cameras.\n\n\
    Typical use:\n  mrsmap odometry --dataset tests/data/fr3_teddy_8 --camera robot_config/cameras/tum_fr3.toml --out traj.txt\n  \
    mrsmap eval rpe tests/data/fr3_teddy_8/groundtruth.txt traj.txt"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// The tracker and a camera driver as two processes on the 8 real frames the
    /// repository ships: every pose printed with its error against motion capture.
    ///
    /// Run it from the repository root (the defaults are relative paths).
    Demo(DemoArgs),
    /// Frame-to-frame RGB-D odometry over a TUM RGB-D dataset; writes a TUM trajectory.
    ///
    /// Each frame's surfel map is registered to the previous frame's map and the poses
    /// are chained from the ground-truth pose of the first frame (identity without
    /// groundtruth.txt). The trajectory holds world_from_camera, stamped with the depth
    /// images' timestamps. With ground truth, the RPE is printed at the end, and how many
    /// of the registrations' predicted standard deviations (Eq. 6) the errors are.
    Odometry(OdometryArgs),
    /// Key-view SLAM over a TUM RGB-D dataset, fused into a model file (paper §5.1)
    ///
    /// Every frame is registered to its reference key view; key views are added as the
    /// camera moves, loop closures are found by randomised extra registrations validated
    /// by the matching likelihood, and the pose graph is optimised one step per frame
    /// and to convergence at the end. With --object, only what lies inside the object's
    /// volume of interest enters the model, expressed in the object frame (z up from the
    /// support plane, which is fitted to the data).
    ///
    /// Example (the teddy model the tracker uses):
    ///   mrsmap map --dataset ../shared/data/tum/fr3_teddy_first200 --camera robot_config/cameras/tum_fr3.toml \
    ///     --object robot_config/objects/teddy.toml --max-frames 100 --out models/teddy.mrsm --trajectory slam.txt
    #[command(verbatim_doc_comment)]
    Map(MapArgs),
    /// Inspect model files: their description, or a picture of their surfels.
    #[command(subcommand)]
    Model(ModelCommand),
    /// Camera driver: publishes a TUM RGB-D sequence (--dataset) or an MCAP recording
    /// (--mcap) over iceoryx2 shared memory.
    ///
    /// Frames go to the service `<SERVICE>/rgbd/vga` (or `/qvga` with --qvga), written
    /// straight into loaned samples; an event of the same name wakes subscribers. Stop
    /// with Ctrl-C. Stamps: the depth images' (capture) and the send time.
    Camera(CameraArgs),
    /// The tracker: RGB-D frames in over iceoryx2, 6-DoF object poses out (paper §5.2).
    ///
    /// Loads the models and allocates everything at start-up, then per frame: waits on
    /// the camera's event (no polling), takes the newest frame (stale ones are dropped),
    /// builds a scene map of the pixels around each object, registers it to the object's
    /// model and publishes `camera_from_object` with covariance, quality and status on
    /// `mrsmap/poses`. Ctrl-C or SIGTERM stop it cleanly.
    ///
    /// With --dataset it runs the same step on every frame of a recorded sequence
    /// instead (no iceoryx2), and reports the error against the ground truth and how
    /// well the published covariance describes it.
    Track(TrackArgs),
    /// Control-stack client: subscribes to the tracker's poses and prints them (and
    /// writes TUM trajectories with --out). The example to copy into a robot.
    Poses(PosesArgs),
    /// Detector client: sends one detection to the running tracker and reports the outcome
    ///
    /// The tracker registers the next frame from the detected pose and resumes tracking
    /// if the registration's quality is good; by default only an object that is lost or
    /// initialising is re-initialised (--always: also one being tracked). Exits 0 when
    /// the object is tracked afterwards, 1 when it was not found there. The message
    /// (MrsmapObjectDetection, docs/wire-format.md) is what a detector in C++ or Python
    /// sends on the tracker's detections.service.
    ///
    /// Example (the teddy, 0.9 m in front of the camera):
    ///   mrsmap detect --object teddy --pose 0.05 0.1 0.9 0 0 0 1
    #[command(verbatim_doc_comment)]
    Detect(DetectArgs),
    /// Offline: the tracker's per-frame step on every frame of an MCAP recording
    ///
    /// Reads ROS 2 (sensor_msgs/msg/Image + CameraInfo, CDR) or Foxglove (RawImage +
    /// CameraCalibration, protobuf) recordings, through the file's index when it has one
    /// (memory stays bounded by the chunk size), streaming otherwise; a truncated file is
    /// replayed up to the damage. Colour and depth are paired by header stamp (≤ 20 ms).
    /// Writes poses as MCAP (ROS 2 PoseWithCovarianceStamped per object and
    /// foxglove.PosesInFrame, in the camera's optical frame, so Foxglove draws them over
    /// the images) and TUM trajectories. The same input gives byte-identical output at any
    /// thread count.
    ///
    /// Example:
    ///   mrsmap convert tum-to-mcap tests/data/fr3_teddy_8 --out teddy.mcap
    ///   mrsmap replay --input teddy.mcap --config robot_config/tracker.toml --out poses.mcap --trajectory traj.txt
    #[command(verbatim_doc_comment)]
    Replay(ReplayArgs),
    /// Convert recordings (TUM RGB-D → MCAP).
    #[command(subcommand)]
    Convert(ConvertCommand),
    /// Synthetic RGB-D sequences with exact ground truth, rendered from a scene file
    ///
    /// Textured meshes (Wavefront OBJ with a PNG or JPEG texture) and boxes with a
    /// procedural texture, seen along each of the scene's camera paths through a model
    /// of a structured-light depth sensor (a Kinect v1 by default: disparity noise and
    /// quantisation, projector shadows, dropouts at edges, colour noise). Each sequence
    /// becomes a TUM RGB-D folder OUT/<sequence> (rgb/, depth/, rgb.txt, depth.txt,
    /// associations.txt, groundtruth.txt, SOURCE.txt) that `odometry`, `map`, `track
    /// --dataset` and `eval` read as they read the benchmark's. The same scene gives the
    /// same images, byte for byte. Each folder is written beside its name and renamed
    /// when complete; Ctrl-C keeps the frames so far as a complete, shorter sequence.
    ///
    /// Example (objects on a table: a model orbit and a held-out tracking run):
    ///   mrsmap synth --scene scripts/scenes/ycb_table.toml --out /tmp/ycb
    ///   mrsmap map --dataset /tmp/ycb/model --camera robot_config/cameras/tum_fr3.toml \
    ///     --object scripts/scenes/ycb_table/banana.toml --out banana.mrsm
    #[command(verbatim_doc_comment)]
    Synth(SynthArgs),
    /// Trajectory errors as the TUM benchmark defines them (agrees with `evo`).
    #[command(subcommand)]
    Eval(EvalCommand),
    /// Time map building and registration per frame at VGA and QVGA (images decoded
    /// beforehand, not timed); prints a Markdown table.
    ///
    /// Before and after the runs it times a fixed arithmetic loop on one thread (how fast
    /// a core is now: on a virtual machine a busy host can halve it) and on all threads
    /// against one (how many of the requested threads really got a core: another load
    /// can take one). When either falls short, the times are slower than the machine
    /// can be. Record those lines with the figures.
    ///
    /// It also prints the processor (the same binary runs at other speeds on another
    /// machine type, and the loop's quiet time differs too) and the instruction set the
    /// binary was compiled for: a build for the robot's own CPU
    /// (`RUSTFLAGS="-C target-cpu=native" cargo build --release`) is faster than the
    /// portable default, with the same trajectories bit for bit on the machines measured
    /// (docs/benchmarks.md).
    Bench(BenchArgs),
}

impl Command {
    /// Whether the command's job is output that may go into a pipe (a table, a report,
    /// poses): killed by SIGPIPE when the reader goes away, as Unix tools are. Not the
    /// processes that talk over iceoryx2 and must outlive their stdout (the live
    /// tracker, the camera driver, the demo that runs both).
    pub fn prints_for_a_pipe(&self) -> bool {
        match self {
            Command::Track(a) => a.dataset.is_some(),
            Command::Camera(_) | Command::Demo(_) => false,
            _ => true,
        }
    }
}

/// Runs a subcommand; its exit status (130: stopped early by Ctrl-C or SIGTERM, the
/// outputs written for the frames before).
pub fn run(command: Command) -> Result<ExitCode> {
    let done = |r: Result<()>| r.map(|()| ExitCode::SUCCESS);
    match command {
        Command::Demo(a) => done(commands::demo(a)),
        Command::Odometry(a) => commands::odometry(a),
        Command::Map(a) => commands::map(a),
        Command::Model(c) => done(commands::model(c)),
        Command::Camera(a) => done(commands::camera(a)),
        Command::Track(a) => commands::track(a),
        Command::Poses(a) => done(commands::poses(a)),
        Command::Detect(a) => done(commands::detect(a)),
        Command::Replay(a) => commands::replay(a),
        Command::Convert(c) => commands::convert(c),
        Command::Synth(a) => commands::synth(a),
        Command::Eval(c) => done(commands::eval(c)),
        Command::Bench(a) => done(bench::bench(a)),
    }
}

/// The text of a failed command for a person: `error: …`, then each cause that the
/// messages before it do not already say (library errors name their cause in their own
/// message, for callers that print only that). No backtrace: these are errors in the
/// input or the environment, and the message names what was wrong; a panic still prints
/// one under `RUST_BACKTRACE`.
pub fn report(error: &anyhow::Error) -> String {
    let mut text = format!("error: {error}");
    let mut said = error.to_string();
    for cause in error.chain().skip(1) {
        let cause = cause.to_string();
        if !said.contains(&cause) {
            text.push_str(&format!("\n  caused by: {cause}"));
        }
        said = cause;
    }
    text
}

#[cfg(test)]
mod tests {
    use super::report;
    use anyhow::Context;

    #[test]
    fn a_report_states_each_cause_once() {
        let io = || Err::<(), _>(std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"));
        // A cause already in the message above it is not repeated…
        let e = io().context("cannot read /x.toml: no such file").unwrap_err();
        assert_eq!(report(&e), "error: cannot read /x.toml: no such file");
        // …one that is not, is.
        let e = io().context("opening dataset /d").unwrap_err();
        assert_eq!(report(&e), "error: opening dataset /d\n  caused by: no such file");
    }
}
