//! `mrsmap`: multi-resolution surfel maps on the command line.

use anyhow::Result;
use clap::{Args, Parser, Subcommand};
use mrsmap::app;
use mrsmap::eval::{ErrorStats, associate, ate_translation, rpe_translation};
use mrsmap::io::tum::Trajectory;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "mrsmap",
    version,
    about = "Multi-resolution surfel maps: RGB-D map building, registration and odometry",
    long_about = "Multi-resolution surfel maps (Stückler & Behnke, JVCI 2014) for RGB-D cameras.\n\n\
    Typical use:\n  mrsmap odometry --dataset tests/data/fr3_teddy_6 --camera robot_config/cameras/tum_fr3.toml --out traj.txt\n  \
    mrsmap eval rpe tests/data/fr3_teddy_6/groundtruth.txt traj.txt"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Frame-to-frame RGB-D odometry over a TUM RGB-D dataset; writes a TUM trajectory.
    ///
    /// Each frame's surfel map is registered to the previous frame's map and the poses
    /// are chained from the ground-truth pose of the first frame (identity without
    /// groundtruth.txt). The trajectory holds world_from_camera, stamped with the depth
    /// images' timestamps. With ground truth, the RPE is printed at the end.
    Odometry(OdometryArgs),
    /// Trajectory errors as the TUM benchmark defines them (agrees with `evo`).
    #[command(subcommand)]
    Eval(EvalCommand),
    /// Time map building and registration per frame at VGA and QVGA (images decoded
    /// beforehand, not timed); prints a Markdown table.
    Bench(BenchArgs),
}

#[derive(Args)]
struct OdometryArgs {
    /// Dataset folder in TUM layout (rgb/, depth/, rgb.txt + depth.txt or associations.txt,
    /// optional groundtruth.txt).
    #[arg(long)]
    dataset: PathBuf,
    /// Camera file, e.g. robot_config/cameras/tum_fr1.toml.
    #[arg(long)]
    camera: PathBuf,
    /// Output trajectory (TUM format: stamp tx ty tz qx qy qz qw).
    #[arg(long)]
    out: PathBuf,
    /// Also write per-frame timings: stamp,build_ms,register_ms,associations,iterations.
    #[arg(long)]
    timings: Option<PathBuf>,
    /// Worker threads [default: all cores]. Results are identical for any count.
    #[arg(long)]
    threads: Option<usize>,
    /// Process at most this many frames.
    #[arg(long)]
    max_frames: Option<usize>,
    /// Halve images and intrinsics on load (QVGA from VGA data).
    #[arg(long)]
    qvga: bool,
}

#[derive(Subcommand)]
enum EvalCommand {
    /// Relative pose error (translation) at a fixed frame delta.
    Rpe {
        /// Reference trajectory (e.g. groundtruth.txt).
        gt: PathBuf,
        /// Estimated trajectory.
        est: PathBuf,
        /// Frame delta.
        #[arg(long, default_value_t = 1)]
        delta: usize,
        /// Maximum time difference for associating stamps (s).
        #[arg(long, default_value_t = 0.02)]
        max_diff: f64,
    },
    /// Absolute trajectory error after rigid (Horn) alignment.
    Ate {
        /// Reference trajectory (e.g. groundtruth.txt).
        gt: PathBuf,
        /// Estimated trajectory.
        est: PathBuf,
        /// Maximum time difference for associating stamps (s).
        #[arg(long, default_value_t = 0.02)]
        max_diff: f64,
    },
}

#[derive(Args)]
struct BenchArgs {
    /// Dataset folder in TUM layout.
    #[arg(long)]
    dataset: PathBuf,
    /// Camera file.
    #[arg(long)]
    camera: PathBuf,
    /// Number of frames to use (default: up to 200, all of the teddy sequence).
    #[arg(long, default_value_t = 200)]
    frames: usize,
    /// Passes over the frames.
    #[arg(long, default_value_t = 3)]
    passes: usize,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Image sizes to run.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "vga,qvga")]
    resolution: Vec<app::bench::Resolution>,
}

fn print_stats(title: &str, s: &ErrorStats) {
    println!("{title} ({} pairs/poses)", s.count);
    println!("  rmse   {:.4} mm", s.rmse * 1e3);
    println!("  mean   {:.4} mm", s.mean * 1e3);
    println!("  median {:.4} mm", s.median * 1e3);
    println!("  std    {:.4} mm", s.std * 1e3);
    println!("  min    {:.4} mm", s.min * 1e3);
    println!("  max    {:.4} mm", s.max * 1e3);
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Odometry(a) => {
            let job = app::odometry::OdometryJob {
                dataset: a.dataset,
                camera: a.camera,
                out: a.out,
                timings: a.timings,
                threads: a.threads,
                max_frames: a.max_frames,
                qvga: a.qvga,
                params: Default::default(),
            };
            let summary = app::odometry::run(&job)?;
            app::odometry::print_summary(&job, &summary);
        }
        Command::Eval(EvalCommand::Rpe { gt, est, delta, max_diff }) => {
            let (g, e) = (Trajectory::read(&gt)?, Trajectory::read(&est)?);
            let (r, p) = associate(&g, &e, max_diff)?;
            let errors = rpe_translation(&r, &p, delta)?;
            print_stats(&format!("RPE translation, delta {delta} frame(s)"), &ErrorStats::of(&errors));
        }
        Command::Eval(EvalCommand::Ate { gt, est, max_diff }) => {
            let (g, e) = (Trajectory::read(&gt)?, Trajectory::read(&est)?);
            let (r, p) = associate(&g, &e, max_diff)?;
            let errors = ate_translation(&r, &p)?;
            print_stats("ATE translation after rigid alignment", &ErrorStats::of(&errors));
        }
        Command::Bench(a) => {
            let job = app::bench::BenchJob {
                dataset: a.dataset,
                camera: a.camera,
                frames: a.frames,
                passes: a.passes,
                threads: a.threads,
                resolutions: a.resolution,
            };
            let results = app::bench::run(&job)?;
            let threads = a.threads.unwrap_or_else(rayon::current_num_threads);
            app::bench::print(&results, threads);
        }
    }
    Ok(())
}
