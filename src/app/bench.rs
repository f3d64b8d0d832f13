//! `mrsmap bench`: time map building and registration per frame on real frames.
//!
//! Frames are decoded once up front (decoding is not timed); each pass builds the map of
//! every frame and registers it to the previous one, as odometry does. The first frame
//! of each pass (nothing to register to) is not counted.

use super::report::percentile;
use crate::frame::RgbdFrame;
use crate::geometry::{CameraModel, Pose};
use crate::io::camera_file::read_camera;
use crate::io::frames::FrameLoader;
use crate::io::tum::TumDataset;
use crate::odometry::{Odometry, OdometryParams, TrackOutcome};
use anyhow::{Context, Result, bail};
use std::path::PathBuf;
use std::time::Instant;

/// What to benchmark.
#[derive(Debug, Clone)]
pub struct BenchJob {
    /// Dataset folder.
    pub dataset: PathBuf,
    /// Camera file.
    pub camera: PathBuf,
    /// Frames to use.
    pub frames: usize,
    /// Passes over the frames.
    pub passes: usize,
    /// Worker threads (default: all cores).
    pub threads: Option<usize>,
    /// Run at VGA (full size) and/or QVGA (halved).
    pub resolutions: Vec<Resolution>,
}

/// An image size to benchmark.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Resolution {
    /// The dataset's own size (640×480 for TUM).
    Vga,
    /// Halved on load (320×240).
    Qvga,
}

/// Timings of one resolution (ms per frame).
#[derive(Debug, Clone)]
pub struct BenchResult {
    /// `"VGA"` or `"QVGA"`.
    pub label: &'static str,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Map building per frame.
    pub build_ms: Vec<f64>,
    /// Registration per frame.
    pub register_ms: Vec<f64>,
    /// Building + registration per frame.
    pub total_ms: Vec<f64>,
    /// Registrations that failed.
    pub failures: usize,
}

struct Decoded {
    stamp_ns: u64,
    rgb: Vec<u8>,
    depth: Vec<u16>,
}

fn decode(dataset: &TumDataset, camera: CameraModel, half: bool, n: usize) -> Result<(CameraModel, Vec<Decoded>)> {
    let mut loader = FrameLoader::new(camera, half);
    let mut out = Vec::new();
    for entry in dataset.frames.iter().take(n) {
        let f = loader.load(entry)?;
        out.push(Decoded { stamp_ns: f.stamp_ns, rgb: f.rgb.to_vec(), depth: f.depth.to_vec() });
    }
    Ok((loader.camera(), out))
}

fn run_one(
    job: &BenchJob,
    label: &'static str,
    camera: CameraModel,
    frames: &[Decoded],
    pool: &rayon::ThreadPool,
) -> Result<BenchResult> {
    let mut odometry =
        Odometry::new(OdometryParams::default(), camera.width as usize, camera.height as usize, Pose::identity())?;
    let mut r = BenchResult {
        label,
        width: camera.width,
        height: camera.height,
        build_ms: vec![],
        register_ms: vec![],
        total_ms: vec![],
        failures: 0,
    };
    for _ in 0..job.passes {
        odometry.reset(Pose::identity());
        for (i, d) in frames.iter().enumerate() {
            let frame = RgbdFrame::new(d.stamp_ns, camera, &d.rgb, &d.depth)?;
            let t0 = Instant::now();
            pool.install(|| odometry.build(&frame))?;
            let t1 = Instant::now();
            let outcome = pool.install(|| odometry.track());
            let t2 = Instant::now();
            if matches!(outcome, TrackOutcome::Failed(_)) {
                r.failures += 1;
            }
            // The first frame of a pass has nothing to register to (and the very first
            // one also fills the ray table): not a steady-state frame.
            if i == 0 {
                continue;
            }
            let (b, g) = ((t1 - t0).as_secs_f64() * 1e3, (t2 - t1).as_secs_f64() * 1e3);
            r.build_ms.push(b);
            r.register_ms.push(g);
            r.total_ms.push(b + g);
        }
    }
    Ok(r)
}

/// Runs the benchmark at each requested resolution.
pub fn run(job: &BenchJob) -> Result<Vec<BenchResult>> {
    if job.frames < 2 {
        bail!("--frames must be at least 2");
    }
    let camera = read_camera(&job.camera)?;
    let dataset = TumDataset::open(&job.dataset).with_context(|| format!("opening {}", job.dataset.display()))?;
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(t) = job.threads {
        pool = pool.num_threads(t);
    }
    let pool = pool.build()?;
    let mut out = Vec::new();
    for &res in &job.resolutions {
        let (label, half) = match res {
            Resolution::Vga => ("VGA", false),
            Resolution::Qvga => ("QVGA", true),
        };
        let (cam, frames) = decode(&dataset, camera, half, job.frames)?;
        out.push(run_one(job, label, cam, &frames, &pool)?);
    }
    Ok(out)
}

/// Prints results as a Markdown table.
pub fn print(results: &[BenchResult], threads: usize) {
    println!(
        "| resolution | threads | frames | build median / p99 (ms) | register median / p99 (ms) | total median / p99 (ms) | failed |"
    );
    println!("|---|---|---|---|---|---|---|");
    for r in results {
        let f = |v: &[f64]| format!("{:.2} / {:.2}", percentile(v, 0.5), percentile(v, 0.99));
        println!(
            "| {} {}×{} | {} | {} | {} | {} | {} | {} |",
            r.label,
            r.width,
            r.height,
            threads,
            r.total_ms.len(),
            f(&r.build_ms),
            f(&r.register_ms),
            f(&r.total_ms),
            r.failures
        );
    }
}
