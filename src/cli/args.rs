//! The arguments of each subcommand (their doc comments are the `--help` text).

use clap::{Args, Subcommand};
use mrsmap::app;
use std::path::PathBuf;

#[derive(Args)]
pub struct OdometryArgs {
    /// Dataset folder in TUM layout (rgb/, depth/, rgb.txt + depth.txt or associations.txt,
    /// optional groundtruth.txt).
    #[arg(long)]
    pub dataset: PathBuf,
    /// Camera file, e.g. robot_config/cameras/tum_fr1.toml (TOML: width, height, fx, fy, cx,
    /// cy, depth_scale_m, and optionally distortion: 5 or 8 coefficients in OpenCV order).
    #[arg(long)]
    pub camera: PathBuf,
    /// Output trajectory (TUM format: stamp tx ty tz qx qy qz qw).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write per-frame timings: stamp,build_ms,register_ms,associations,iterations.
    #[arg(long)]
    pub timings: Option<PathBuf>,
    /// Worker threads [default: all cores]. Results are identical for any count.
    #[arg(long, value_parser = at_least_one::<usize>)]
    pub threads: Option<usize>,
    /// Process at most this many frames.
    #[arg(long, value_parser = at_least_one::<usize>)]
    pub max_frames: Option<usize>,
    /// Halve images and intrinsics on load (QVGA from VGA data).
    #[arg(long)]
    pub qvga: bool,
    /// Resolution factor λ of the map: the finest cell at distance r is about 2·λ·r²
    /// (paper §3.3). Smaller values use finer cells nearby: more accurate, slower.
    #[arg(long, default_value_t = 0.01)]
    pub lambda: f64,
}

#[derive(Args)]
pub struct MapArgs {
    /// Dataset folder in TUM layout (groundtruth.txt, if present, gives the first pose
    /// and the ATE in the summary).
    #[arg(long)]
    pub dataset: PathBuf,
    /// Camera file, e.g. robot_config/cameras/tum_fr3.toml (TOML: width, height, fx, fy, cx,
    /// cy, depth_scale_m, and optionally distortion: 5 or 8 coefficients in OpenCV order).
    #[arg(long)]
    pub camera: PathBuf,
    /// Object description with the volume of interest, e.g. robot_config/objects/teddy.toml.
    /// Without it the whole scene is modelled in the world frame.
    #[arg(long)]
    pub object: Option<PathBuf>,
    /// Model file to write (e.g. models/teddy.mrsm). Written atomically.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace --out if it exists.
    #[arg(long)]
    pub force: bool,
    /// Camera trajectory to write (TUM format, world_from_camera, depth timestamps).
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    /// Worker threads [default: all cores]. Results are identical for any count.
    #[arg(long, value_parser = at_least_one::<usize>)]
    pub threads: Option<usize>,
    /// Use at most this many frames, from the first.
    #[arg(long, value_parser = at_least_one::<usize>)]
    pub max_frames: Option<usize>,
    /// Seed of the randomised loop-closure draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Resolution factor λ of the maps (finest cell at distance r ≈ 2·λ·r²). The default
    /// is finer than odometry's 0.01: it halves the bias of coarse cells over the wide
    /// baselines between key views (ATE on fr3_teddy: 12.0 mm against 14.6 mm).
    #[arg(long, default_value_t = 0.007)]
    pub lambda: f64,
}

#[derive(Args)]
pub struct CameraArgs {
    /// Dataset folder in TUM layout.
    #[arg(long, required_unless_present = "mcap", conflicts_with = "mcap")]
    pub dataset: Option<PathBuf>,
    /// An MCAP recording to publish instead (see `mrsmap replay --help` for what it may
    /// hold); 640x480 recordings go out as VGA (QVGA with --qvga), 320x240 as QVGA.
    #[arg(long)]
    pub mcap: Option<PathBuf>,
    /// Camera file of the dataset (with --mcap: replaces the recording's CameraInfo).
    #[arg(long, required_unless_present = "mcap")]
    pub camera: Option<PathBuf>,
    #[command(flatten)]
    pub topics: TopicArgs,
    /// Service prefix; the tracker's config names the same (camera.service).
    #[arg(long, default_value = mrsmap::io::ipc::DEFAULT_CAMERA_SERVICE, value_parser = service_name)]
    pub service: String,
    /// Frames per second (0: as fast as possible).
    #[arg(long, default_value_t = 30.0)]
    pub rate: f64,
    /// Publish 320×240 frames (images and intrinsics halved).
    #[arg(long)]
    pub qvga: bool,
    /// Start over after the last frame, until stopped.
    #[arg(long = "loop")]
    pub repeat: bool,
    /// Play the frames to the last, back to the first, and so on, until stopped: the
    /// motion never jumps (a loop jumps back to the first pose, which costs a tracker
    /// two long registrations per loop). Datasets only.
    #[arg(long, conflicts_with_all = ["repeat", "mcap"])]
    pub bounce: bool,
    /// Skip this many frames at the start.
    #[arg(long, default_value_t = 0)]
    pub first_frame: usize,
    /// Stop after this many frames.
    #[arg(long, value_parser = at_least_one::<u64>)]
    pub max_frames: Option<u64>,
}

#[derive(Args)]
pub struct TrackArgs {
    /// Tracker configuration, e.g. robot_config/tracker.toml (`--print-default-config`
    /// writes one with every key at its default and what it does).
    #[arg(long, required_unless_present = "print_default_config")]
    pub config: Option<PathBuf>,
    /// Print the whole tracker configuration with every key at its default, each
    /// explained, and one example object, then exit (`mrsmap track
    /// --print-default-config > my_robot.toml`, then edit the camera service and the objects).
    #[arg(long, exclusive = true)]
    pub print_default_config: bool,
    /// Check the configuration and exit: read it, load and check every model, allocate
    /// the tracker for the configured image size and plan where its workers run, as the
    /// tracker does at start-up, without opening a service; then print what it would run
    /// and where each start pose puts its object (a warning, exit code 3, if out of a
    /// camera's view: e.g. a pose given as object_from_camera). Exit code 1: it would not
    /// start.
    #[arg(long, requires = "config", conflicts_with_all = ["dataset", "record", "max_frames", "idle_timeout"])]
    pub check: bool,
    /// Stop after this many frames (live mode).
    #[arg(long, value_parser = at_least_one::<u64>)]
    pub max_frames: Option<u64>,
    /// Override the config's camera.service.
    #[arg(long, value_parser = service_name)]
    pub camera_service: Option<String>,
    /// Override the config's poses.service.
    #[arg(long, value_parser = service_name)]
    pub poses_service: Option<String>,
    /// Override the config's detections.service (where `mrsmap detect` and external
    /// detectors send detections).
    #[arg(long, value_parser = service_name)]
    pub detections_service: Option<String>,
    /// Stop after this many seconds without a frame (live mode).
    #[arg(long)]
    pub idle_timeout: Option<f64>,
    /// Record the frames received and the poses published into this MCAP file (live
    /// mode), finished on Ctrl-C/SIGTERM; `mrsmap replay` reads it.
    #[arg(long, conflicts_with = "dataset")]
    pub record: Option<PathBuf>,
    /// Keep only the frames received in the last this many seconds in the recording
    /// (held in memory, about 46 MB per second of VGA at 30 Hz, 5 bytes a pixel, allocated at start, and
    /// written at the end; refused if that is more than half of the memory available).
    #[arg(long, requires = "record")]
    pub record_last: Option<f64>,
    /// Replace the --record file if it exists (without it, an existing file is an error:
    /// a live run cannot be recorded again).
    #[arg(long, requires = "record")]
    pub force: bool,
    /// Offline: track every frame of this TUM dataset instead of listening to a camera.
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// Offline: camera file of the dataset.
    #[arg(long, requires = "dataset")]
    pub camera: Option<PathBuf>,
    /// Offline: skip this many frames.
    #[arg(long, default_value_t = 0, requires = "dataset")]
    pub first_frame: usize,
    /// Offline: track only every n-th frame (1–30; as `replay --every`), as a tracker
    /// sees the camera when it takes the newest frame and each step lasts n camera periods
    /// (a shared CPU, a faster camera): the motion between tracked frames is n times larger.
    #[arg(long, default_value_t = 1, requires = "dataset", value_parser = clap::value_parser!(u32).range(1..=30))]
    pub every: u32,
    /// Offline: halve images and intrinsics on load.
    #[arg(long, requires = "dataset")]
    pub qvga: bool,
    /// Offline: start at the ground-truth pose (dataset ground truth + the model's
    /// world_from_model) instead of the configured camera_from_object.
    #[arg(long, requires = "dataset")]
    pub start_at_ground_truth: bool,
    /// Offline: before each frame, re-initialise every object that is not tracking at its
    /// ground-truth pose, as a perfect object detector would (`Tracker::reinitialise`).
    /// Measures the tracker apart from its own search after a loss; the summary counts
    /// the re-initialisations. Implies --start-at-ground-truth.
    #[arg(long, requires = "dataset")]
    pub reinitialise_at_ground_truth: bool,
    /// Offline, with --reinitialise-at-ground-truth: a detector that errs by this much,
    /// a shift of MM and a turn of DEG about random axes (fixed seed), instead of a
    /// perfect one.
    #[arg(long, num_args = 2, value_names = ["MM", "DEG"], requires = "reinitialise_at_ground_truth")]
    pub detector_error: Option<Vec<f64>>,
    /// Offline, with --reinitialise-at-ground-truth: a detector this many frames late
    /// (it reports the pose in the frame that many frames before).
    #[arg(long, default_value_t = 0, requires = "reinitialise_at_ground_truth")]
    pub detector_latency: usize,
    /// Offline: write object_from_camera per object (TUM format).
    #[arg(long, requires = "dataset")]
    pub trajectory: Option<PathBuf>,
    /// Offline: into this folder (created if missing), a picture per tracked frame
    /// (<depth stamp>.overlay.png, replacing one of an earlier run): the colour image with each tracked model drawn at its
    /// estimated pose, green where the depth image agrees with the model, red where the
    /// camera sees through it (a wrong pose), blue where something nearer hides it, grey
    /// without depth; a green frame around it when every object is tracked, red when one
    /// is not. About 0.5 MB a VGA frame: pick frames with --first-frame, --max-frames, --every.
    #[arg(long, requires = "dataset", value_name = "DIR")]
    pub overlay: Option<PathBuf>,
}

#[derive(Subcommand)]
pub enum ModelCommand {
    /// Describe a model file: frame, source, parameters, volume, root statistics, surfels.
    Info {
        /// Model file.
        file: PathBuf,
    },
    /// Draw a model's surfels in colour (shaded by their normals) into a PNG.
    Render {
        /// Model file.
        file: PathBuf,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
        /// Viewing angle around the model's z axis (degrees) [default: the side most
        /// surfels face, which is where the camera was].
        #[arg(long, allow_negative_numbers = true)]
        azimuth: Option<f64>,
        /// Viewing angle above the model's xy plane (degrees).
        #[arg(long, default_value_t = 25.0, allow_negative_numbers = true)]
        elevation: f64,
        /// Distance from the model (m; to the middle of its extent as seen) [default: the least that holds the whole model in view].
        #[arg(long, allow_negative_numbers = true)]
        distance: Option<f64>,
        /// Image width (pixels).
        #[arg(long, default_value_t = 800)]
        width: u32,
        /// Image height (pixels).
        #[arg(long, default_value_t = 600)]
        height: u32,
    },
}

#[derive(Subcommand)]
pub enum EvalCommand {
    /// How well the tracker detects failed registrations: precision and recall against
    /// ground truth, from priors perturbed at random.
    ///
    /// Two tables: the quality signal alone per threshold, and the tracker's rule
    /// (quality below min_quality, or the depth image seeing through more than
    /// max_free_space of the model) per free-space threshold, each with the failures
    /// missed and those of them farther than 200 mm from the truth.
    TrackingQuality(QualityArgs),
    /// Relative pose error (translation) at a fixed frame delta.
    Rpe {
        /// Reference trajectory (e.g. groundtruth.txt).
        gt: PathBuf,
        /// Estimated trajectory.
        est: PathBuf,
        /// Frame delta (1: consecutive frames, the TUM benchmark's setting).
        #[arg(long, default_value_t = 1, value_parser = at_least_one::<u64>)]
        delta: u64,
        #[command(flatten)]
        association: AssociationArgs,
        /// Also draw the error of every frame pair over time into this SVG file (median
        /// and RMSE marked, the largest labelled with its time).
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Absolute trajectory error after rigid (Horn) alignment.
    Ate {
        /// Reference trajectory (e.g. groundtruth.txt).
        gt: PathBuf,
        /// Estimated trajectory.
        est: PathBuf,
        #[command(flatten)]
        association: AssociationArgs,
        /// Also draw both trajectories seen from above (the aligned estimate over the
        /// reference, each position joined to its reference) and the error over time
        /// into this SVG file.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
}

/// How the estimate's stamps are paired with the reference's.
#[derive(Args)]
pub struct AssociationArgs {
    /// Maximum time difference for associating stamps (s).
    #[arg(long, default_value_t = 0.02)]
    pub max_diff: f64,
    /// Seconds added to the estimate's stamps before associating (the TUM scripts'
    /// `--offset`, evo's `--t_offset`). The benchmark's figures use 0; a non-zero value
    /// tests for a clock offset between the camera and the ground truth, e.g. `--offset
    /// -0.02` compares each estimate with the ground truth 20 ms earlier.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub offset: f64,
}

#[derive(Args)]
pub struct BenchArgs {
    /// Dataset folder in TUM layout.
    #[arg(long)]
    pub dataset: PathBuf,
    /// Camera file.
    #[arg(long)]
    pub camera: PathBuf,
    /// Number of frames to use, at least 2 (default: up to 200, all of the teddy sequence).
    #[arg(long, default_value_t = 200, value_parser = at_least_two)]
    pub frames: usize,
    /// Passes over the frames.
    #[arg(long, default_value_t = 3, value_parser = at_least_one::<usize>)]
    pub passes: usize,
    /// Worker threads [default: all cores].
    #[arg(long, value_parser = at_least_one::<usize>)]
    pub threads: Option<usize>,
    /// Image sizes to run.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "vga,qvga")]
    pub resolution: Vec<app::bench::Resolution>,
    /// Key views of the synthetic pose graph whose optimisation step is also timed
    /// (0: not timed).
    #[arg(long, default_value_t = 100)]
    pub graph_key_views: usize,
    /// Also time object tracking with this tracker configuration (frames from
    /// --tracking-first-frame, objects started at their ground-truth pose). One row per
    /// object: its time per frame, split into the scene map (region, gate, map building)
    /// and the registration with the quality (medians), and the frames whose pose was
    /// estimated (an object not found costs less); with several objects, a row for the
    /// whole step. The first frame after start-up, which also computes the camera's ray
    /// table once, is shown in its own column, not in the median and p99.
    #[arg(long)]
    pub tracking_config: Option<PathBuf>,
    /// First frame of the tracking benchmark (the teddy model was learned from 0–99).
    #[arg(long, default_value_t = 100)]
    pub tracking_first_frame: usize,
    /// Idle this many milliseconds before each tracking frame, as a live tracker idles
    /// between camera frames (33 at 30 Hz). 0 runs the frames back to back. Where idle
    /// cores wake slowly (a virtual machine, deep power-saving states) the step is slower
    /// after a gap than back to back; docs/benchmarks.md shows both.
    #[arg(long, default_value_t = 0.0)]
    pub frame_gap_ms: f64,
    /// Resolution factor λ of the maps (see `odometry --help`).
    #[arg(long, default_value_t = 0.01)]
    pub lambda: f64,
    /// Also draw every frame's time into this SVG file: a panel per run (odometry at
    /// each size, tracking per object and size), the frames in the order they ran, the
    /// passes apart, median and p99 marked. A frame slow in every pass is slow by its
    /// data; a slow stretch in one pass only is the machine's (another load, a slowed
    /// core).
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

#[derive(Args)]
pub struct DemoArgs {
    /// Tracker configuration.
    #[arg(long, default_value = "robot_config/tracker.toml")]
    pub config: PathBuf,
    /// Dataset the camera driver publishes (the repository ships an 8-frame clip).
    #[arg(long, default_value = "tests/data/fr3_teddy_8")]
    pub dataset: PathBuf,
    /// Camera file of the dataset.
    #[arg(long, default_value = "robot_config/cameras/tum_fr3.toml")]
    pub camera: PathBuf,
    /// Frames per second the driver sends (0: as fast as it can). A tracker slower than
    /// that drops the frames a newer one replaced, as on a robot; the demo then says how
    /// many got no pose and which rate would show every one.
    #[arg(long, default_value_t = 10.0)]
    pub rate: f64,
}

#[derive(Args)]
pub struct QualityArgs {
    /// Tracker configuration (object 0 is measured).
    #[arg(long)]
    pub config: PathBuf,
    /// Dataset with groundtruth.txt.
    #[arg(long)]
    pub dataset: PathBuf,
    /// Camera file of the dataset.
    #[arg(long)]
    pub camera: PathBuf,
    /// First frame (the teddy model was learned from frames 0–99).
    #[arg(long, default_value_t = 100)]
    pub first_frame: usize,
    /// Frames used.
    #[arg(long, default_value_t = 100)]
    pub frames: usize,
    /// Perturbed registrations per frame.
    #[arg(long, default_value_t = 6, value_parser = at_least_one::<usize>)]
    pub trials: usize,
    /// Largest prior shift per axis (m).
    #[arg(long, default_value_t = 0.06)]
    pub max_shift: f64,
    /// Largest prior turn per axis (degrees).
    #[arg(long, default_value_t = 8.6)]
    pub max_turn: f64,
    /// A result farther than this from the truth failed (mm).
    #[arg(long, default_value_t = 50.0)]
    pub fail_mm: f64,
    /// … or turned more than this (degrees).
    #[arg(long, default_value_t = 8.0)]
    pub fail_deg: f64,
    /// Random seed.
    #[arg(long, default_value_t = 3)]
    pub seed: u64,
    /// Also write every registration to this CSV file (`frame,stamp,quality,free_space,
    /// associations,error_mm,error_deg,failed`; error_mm empty without a result), to study
    /// a failure rule of your own.
    #[arg(long, value_name = "FILE")]
    pub trials_csv: Option<PathBuf>,
}

/// Topics of an RGB-D recording.
#[derive(Args)]
pub struct TopicArgs {
    /// Colour images (sensor_msgs/msg/Image or foxglove.RawImage: rgb8, bgr8, rgba8, bgra8;
    /// or CompressedImage of either: JPEG, PNG).
    #[arg(long, default_value = mrsmap::io::recording::DEFAULT_COLOR_TOPIC)]
    pub color_topic: String,
    /// Depth images registered to colour (16UC1/mono16 in mm, 32FC1 in m; or CompressedImage:
    /// 16-bit PNG in mm, image_transport's compressedDepth).
    #[arg(long, default_value = mrsmap::io::recording::DEFAULT_DEPTH_TOPIC)]
    pub depth_topic: String,
    /// Calibration (sensor_msgs/msg/CameraInfo or foxglove.CameraCalibration).
    #[arg(long, default_value = mrsmap::io::recording::DEFAULT_CAMERA_INFO_TOPIC)]
    pub camera_info_topic: String,
}

impl TopicArgs {
    pub fn topics(&self) -> mrsmap::io::recording::RecordingTopics {
        mrsmap::io::recording::RecordingTopics {
            color: self.color_topic.clone(),
            depth: self.depth_topic.clone(),
            camera_info: self.camera_info_topic.clone(),
        }
    }
}

#[derive(Args)]
pub struct ReplayArgs {
    /// The recording (MCAP; ROS 2 CDR or Foxglove protobuf images).
    #[arg(long)]
    pub input: PathBuf,
    /// Tracker configuration, e.g. robot_config/tracker.toml (objects, models, start poses).
    #[arg(long)]
    pub config: PathBuf,
    /// Poses to write (MCAP): geometry_msgs/msg/PoseWithCovarianceStamped on
    /// /mrsmap/<object>/pose, foxglove.PosesInFrame on /mrsmap/poses, the transforms to
    /// each object's frame mrsmap/<object> on /tf, and each model as a PointCloud2 in its
    /// frame on /mrsmap/<object>/model (open it with the recording in Foxglove).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace --out if it exists.
    #[arg(long)]
    pub force: bool,
    /// object_from_camera of each object (TUM format, depth stamps; suffixed by the
    /// object's name when there are several).
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    #[command(flatten)]
    pub topics: TopicArgs,
    /// Camera file to use instead of the recording's calibration messages.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Ground truth of the recording (a TUM trajectory of the camera in the world the
    /// models were mapped in, e.g. motion capture): prints each object's error, through
    /// its model's world_from_model, and how the published covariances describe it.
    #[arg(long)]
    pub groundtruth: Option<PathBuf>,
    /// Track only every n-th frame (the default 1 tracks every frame; none is dropped).
    #[arg(long, default_value_t = 1, value_parser = at_least_one::<usize>)]
    pub every: usize,
    /// Halve images and intrinsics (track at QVGA from a VGA recording).
    #[arg(long)]
    pub qvga: bool,
    /// Stop after this many tracked frames.
    #[arg(long, value_parser = at_least_one::<usize>)]
    pub max_frames: Option<usize>,
    /// Worker threads, reading the recording included [default: the config's `threads`,
    /// else all cores]. The output is identical for any count.
    #[arg(long, value_parser = at_least_one::<usize>)]
    pub threads: Option<usize>,
}

#[derive(Subcommand)]
pub enum ConvertCommand {
    /// A TUM RGB-D sequence as a ROS 2 MCAP recording: sensor_msgs/msg/Image (rgb8 and
    /// 16UC1 depth in mm, or 32FC1 in m) and sensor_msgs/msg/CameraInfo, stamped with the
    /// images' timestamps.
    ///
    /// Example:
    ///   mrsmap convert tum-to-mcap tests/data/fr3_teddy_8 --out teddy.mcap
    #[command(verbatim_doc_comment)]
    TumToMcap(TumToMcapArgs),
}

#[derive(Args)]
pub struct TumToMcapArgs {
    /// Dataset folder in TUM layout.
    pub dataset: PathBuf,
    /// The recording to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace --out if it exists.
    #[arg(long)]
    pub force: bool,
    /// Camera file [default: the TUM camera the folder's name gives (fr1/fr2/fr3)].
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Depth encoding: 16UC1 (mm, what ROS 2 drivers publish) or 32FC1 (m; keeps TUM's
    /// 0.2 mm units exactly).
    #[arg(long, default_value = "16UC1", value_parser = ["16UC1", "32FC1"])]
    pub depth_encoding: String,
    /// Chunk compression.
    #[arg(long, default_value = "zstd", value_parser = ["zstd", "lz4"])]
    pub compression: String,
    /// Chunk size: a chunk is closed once its messages reach this many bytes
    /// (uncompressed). The default holds one VGA frame per chunk; `ros2 bag record -s mcap`
    /// writes 786432 by default, its `zstd_small` preset 4194304. Readers decompress a
    /// whole chunk at a time: small chunks spread the work evenly over the frames. At most
    /// 67108864 (64 MiB).
    #[arg(long, default_value_t = mrsmap::io::mcap_write::DEFAULT_CHUNK_BYTES, value_parser = chunk_size)]
    pub chunk_size: u64,
    #[command(flatten)]
    pub topics: TopicArgs,
    /// Skip this many frames.
    #[arg(long, default_value_t = 0)]
    pub first_frame: usize,
    /// Convert at most this many frames.
    #[arg(long, value_parser = at_least_one::<usize>)]
    pub max_frames: Option<usize>,
}

#[derive(Args)]
pub struct SynthArgs {
    /// Scene file (TOML: camera, meshes, boxes, sensor, sequences; see scripts/scenes/).
    #[arg(long)]
    pub scene: PathBuf,
    /// Folder that receives one TUM RGB-D folder per sequence (`OUT/<sequence>`).
    #[arg(long)]
    pub out: PathBuf,
    /// Render only this sequence (repeat for several) [default: all of the scene's].
    #[arg(long = "sequence")]
    pub sequences: Vec<String>,
    /// Replace sequence folders that exist.
    #[arg(long)]
    pub force: bool,
    /// Render at most this many frames of each sequence.
    #[arg(long, value_parser = at_least_one::<usize>)]
    pub max_frames: Option<usize>,
}

/// A count such as `--max-frames`: zero would run nothing and report nothing, so it is
/// refused at once.
pub(super) fn at_least_one<T>(text: &str) -> Result<T, String>
where
    T: std::str::FromStr<Err = std::num::ParseIntError> + From<u8> + PartialEq,
{
    match text.parse::<T>() {
        Ok(n) if n == T::from(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(e.to_string()),
    }
}

/// A frame count of at least 2 (the benchmark registers each frame to the one before).
fn at_least_two(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(n) if n < 2 => Err("must be at least 2 (each frame is registered to the one before)".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(e.to_string()),
    }
}

/// A chunk size in bytes: at least 1, and small enough that the replay reads it back
/// (`mcap_write::MAX_CHUNK_BYTES`).
fn chunk_size(text: &str) -> Result<u64, String> {
    use mrsmap::io::{mcap_source::MAX_RECORD_BYTES, mcap_write::MAX_CHUNK_BYTES};
    let n = at_least_one::<u64>(text)?;
    if n > MAX_CHUNK_BYTES {
        return Err(format!(
            "must be at most {MAX_CHUNK_BYTES} ({} MiB): a larger chunk could exceed the {} MiB records `mrsmap replay` reads",
            MAX_CHUNK_BYTES >> 20,
            MAX_RECORD_BYTES >> 20
        ));
    }
    Ok(n)
}

/// An iceoryx2 service name (prefix): not empty, or the driver and the tracker would
/// meet on a bare `/rgbd/vga`.
pub(super) fn service_name(text: &str) -> Result<String, String> {
    if text.trim().is_empty() { Err("a service name must not be empty".into()) } else { Ok(text.to_owned()) }
}
