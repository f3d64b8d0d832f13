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
    Typical use:\n  mrsmap odometry --dataset tests/data/fr3_teddy_8 --camera robot_config/cameras/tum_fr3.toml --out traj.txt\n  \
    mrsmap eval rpe tests/data/fr3_teddy_8/groundtruth.txt traj.txt"
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
    /// Key-view SLAM over a TUM RGB-D dataset, fused into a model file (paper §5.1).
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
    Map(MapArgs),
    /// Inspect model files: their description, or a picture of their surfels.
    #[command(subcommand)]
    Model(ModelCommand),
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
    /// Resolution factor λ of the map: the finest cell at distance r is about 2·λ·r²
    /// (paper §3.3). Smaller values use finer cells nearby: more accurate, slower.
    #[arg(long, default_value_t = 0.01)]
    lambda: f64,
}

#[derive(Args)]
struct MapArgs {
    /// Dataset folder in TUM layout (groundtruth.txt, if present, gives the first pose
    /// and the ATE in the summary).
    #[arg(long)]
    dataset: PathBuf,
    /// Camera file, e.g. robot_config/cameras/tum_fr3.toml.
    #[arg(long)]
    camera: PathBuf,
    /// Object description with the volume of interest, e.g. robot_config/objects/teddy.toml.
    /// Without it the whole scene is modelled in the world frame.
    #[arg(long)]
    object: Option<PathBuf>,
    /// Model file to write (e.g. models/teddy.mrsm). Written atomically.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Replace --out if it exists.
    #[arg(long)]
    force: bool,
    /// Camera trajectory to write (TUM format, world_from_camera, depth timestamps).
    #[arg(long)]
    trajectory: Option<PathBuf>,
    /// Worker threads [default: all cores]. Results are identical for any count.
    #[arg(long)]
    threads: Option<usize>,
    /// Use at most this many frames, from the first.
    #[arg(long)]
    max_frames: Option<usize>,
    /// Seed of the randomised loop-closure draws.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Resolution factor λ of the maps (finest cell at distance r ≈ 2·λ·r²). The default
    /// is finer than odometry's 0.01: it halves the bias of coarse cells over the wide
    /// baselines between key views (ATE on fr3_teddy: 12.0 mm against 14.6 mm).
    #[arg(long, default_value_t = 0.007)]
    lambda: f64,
}

#[derive(Subcommand)]
enum ModelCommand {
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
        /// Distance from the model's centre (m) [default: the whole model in view].
        #[arg(long)]
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
    /// Key views of the synthetic pose graph whose optimisation step is also timed.
    #[arg(long, default_value_t = 100)]
    graph_key_views: usize,
    /// Resolution factor λ of the maps (see `odometry --help`).
    #[arg(long, default_value_t = 0.01)]
    lambda: f64,
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

/// Default odometry parameters with the map resolution factor λ.
fn odometry_params(lambda: f64) -> mrsmap::odometry::OdometryParams {
    mrsmap::odometry::OdometryParams {
        map: mrsmap::map::MapParams { lambda, ..Default::default() },
        ..Default::default()
    }
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
                params: odometry_params(a.lambda),
            };
            let summary = app::odometry::run(&job)?;
            app::odometry::print_summary(&job, &summary);
        }
        Command::Map(a) => {
            let job = app::mapper::MapJob {
                dataset: a.dataset,
                camera: a.camera,
                object: a.object,
                out: a.out,
                force: a.force,
                trajectory: a.trajectory,
                threads: a.threads,
                max_frames: a.max_frames,
                params: {
                    let mut p = mrsmap::slam::SlamParams { seed: a.seed, ..Default::default() };
                    p.map.lambda = a.lambda;
                    p
                },
            };
            let summary = app::mapper::run(&job)?;
            app::mapper::print_summary(&job, &summary);
        }
        Command::Model(ModelCommand::Info { file }) => print!("{}", app::model_cmd::info(&file)?),
        Command::Model(ModelCommand::Render { file, out, azimuth, elevation, distance, width, height }) => {
            if width == 0 || height == 0 || width > 8192 || height > 8192 {
                anyhow::bail!("--width and --height must be 1..=8192 pixels");
            }
            let view = app::render::View {
                azimuth_deg: azimuth,
                elevation_deg: elevation,
                distance_m: distance,
                width,
                height,
                ..Default::default()
            };
            let drawn = app::model_cmd::render_file(&file, &out, &view)?;
            println!("{drawn} surfels drawn → {}", out.display());
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
                graph_key_views: a.graph_key_views,
                params: odometry_params(a.lambda),
            };
            let results = app::bench::run(&job)?;
            let threads = a.threads.unwrap_or_else(rayon::current_num_threads);
            app::bench::print(&results, threads);
            let (edges, ms) = app::bench::graph_step_ms(job.graph_key_views, 50);
            println!(
                "\npose-graph step (synthetic, {} key views, {edges} edges, 50 on-line steps): median {:.2} ms, p99 {:.2} ms",
                job.graph_key_views,
                app::report::percentile(&ms, 0.5),
                app::report::percentile(&ms, 0.99)
            );
        }
    }
    Ok(())
}
