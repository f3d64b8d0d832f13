//! `mrsmap bench`: time map building and registration per frame on real frames.
//!
//! Frames are decoded once up front (decoding is not timed); each pass builds the map of
//! every frame and registers it to the previous one, as odometry does. The first frame
//! of each pass (nothing to register to) is not counted.

use super::dataset::install_spinning;
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
    /// Key views of the synthetic pose graph whose optimisation step is timed.
    pub graph_key_views: usize,
    /// Odometry parameters (map resolution factor λ and the rest).
    pub params: OdometryParams,
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
    /// Indices into the per-frame times where a pass after the first starts.
    pub pass_starts: Vec<usize>,
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
    let mut odometry = Odometry::new(job.params, camera.width as usize, camera.height as usize, Pose::identity())?;
    let mut r = BenchResult {
        label,
        width: camera.width,
        height: camera.height,
        build_ms: vec![],
        register_ms: vec![],
        total_ms: vec![],
        failures: 0,
        pass_starts: vec![],
    };
    for pass in 0..job.passes {
        if pass > 0 {
            r.pass_starts.push(r.total_ms.len());
        }
        odometry.reset(Pose::identity());
        for (i, d) in frames.iter().enumerate() {
            let frame = RgbdFrame::new(d.stamp_ns, camera, &d.rgb, &d.depth)?;
            let t0 = Instant::now();
            install_spinning(pool, || odometry.build(&frame))?;
            let t1 = Instant::now();
            let outcome = install_spinning(pool, || odometry.track());
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

/// Times of one pose-graph step (ms) on a synthetic graph shaped like a mapping run:
/// `key_views` key views on a circle of 1 m radius around an object, each joined to its
/// predecessor and by loop closures to up to three earlier key views within 0.7 m
/// (about 3.7 edges per key view, as on fr3_teddy), measurements perturbed by 5 mm /
/// 0.01 rad, odometry-chained initial poses. Each of `steps` calls is one on-line step,
/// as the mapper makes one per frame: the first ones converge, the later ones mostly
/// confirm the optimum. Without key views there is nothing to time: `(0, [])`.
pub fn graph_step_ms(key_views: usize, steps: usize) -> (usize, Vec<f64>) {
    use crate::geometry::se3::left_increment;
    use crate::slam::{Edge, EdgeKind, PoseGraph};
    use crate::synthetic::Pcg32;
    use nalgebra::{Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};
    if key_views == 0 {
        return (0, Vec::new());
    }
    let mut rng = Pcg32::new(7);
    let truth: Vec<Pose> = (0..key_views)
        .map(|k| {
            let a = k as f64 / key_views.max(1) as f64 * std::f64::consts::TAU * 1.5;
            let eye = Vector3::new(a.cos(), a.sin(), 0.3 * (3.0 * a).sin());
            let look = UnitQuaternion::face_towards(&-eye, &Vector3::z());
            Pose::from_parts(Translation3::from(eye), look)
        })
        .collect();
    let noise = |rng: &mut Pcg32| {
        left_increment(&Vector6::from_fn(
            |i, _| if i < 3 { rng.uniform(-0.005, 0.005) } else { rng.uniform(-0.01, 0.01) },
        ))
    };
    let information = Matrix6::from_diagonal(&Vector6::new(2.5e5, 2.5e5, 2.5e5, 1e5, 1e5, 1e5));
    let mut graph = PoseGraph::new();
    let mut estimate = truth[0];
    graph.add_vertex(estimate);
    for k in 1..key_views {
        let z = noise(&mut rng) * truth[k - 1].inverse() * truth[k];
        estimate *= z;
        graph.add_vertex(estimate);
        let _ = graph.add_edge(Edge { from: k - 1, to: k, measurement: z, information, kind: EdgeKind::KeyView });
        let close: Vec<usize> = (0..k.saturating_sub(1))
            .filter(|&j| (truth[j].translation.vector - truth[k].translation.vector).norm() < 0.7)
            .collect();
        for _ in 0..3.min(close.len()) {
            let j = close[(rng.next_u32() as usize) % close.len()];
            if !graph.connected(j, k) {
                let z = noise(&mut rng) * truth[j].inverse() * truth[k];
                let _ =
                    graph.add_edge(Edge { from: j, to: k, measurement: z, information, kind: EdgeKind::LoopClosure });
            }
        }
    }
    let edges = graph.edges.len();
    let times = (0..steps)
        .map(|_| {
            let t = Instant::now();
            let _ = graph.step();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    (edges, times)
}

/// The vector instruction set this binary was compiled for (`-C target-cpu`, see
/// docs/benchmarks.md "Building for the robot's CPU"): it changes the figures, so it
/// is printed with them.
pub fn instruction_set() -> &'static str {
    if cfg!(target_feature = "avx512f") {
        "AVX-512 (x86-64-v4 or a newer target CPU)"
    } else if cfg!(target_feature = "avx2") {
        "AVX2 (x86-64-v3 or a newer target CPU)"
    } else if cfg!(target_feature = "sse4.2") {
        "SSE4.2 (x86-64-v2)"
    } else if cfg!(target_arch = "x86_64") {
        "SSE2 (the x86-64 baseline, runs on any x86-64)"
    } else {
        std::env::consts::ARCH
    }
}

/// The processor's name as the kernel gives it (`/proc/cpuinfo`; `None` elsewhere): the
/// same binary runs at other speeds on another machine type, so it is printed with the
/// figures, as is the probe loop's time.
pub fn cpu_model() -> Option<String> {
    cpu_model_in(&std::fs::read_to_string("/proc/cpuinfo").ok()?)
}

/// The first `model name` of a `/proc/cpuinfo` text.
fn cpu_model_in(cpuinfo: &str) -> Option<String> {
    cpuinfo.lines().find_map(|line| {
        let (key, value) = line.split_once(':')?;
        (key.trim() == "model name").then(|| value.trim().to_string()).filter(|v| !v.is_empty())
    })
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

/// The tracker's step times of one object (ms).
#[derive(Debug, Clone)]
pub struct ObjectTimes {
    /// The object's name in the configuration.
    pub name: String,
    /// The very first frame after start-up: it also computes the camera's ray table
    /// (once per camera, `RayTable::ensure`) and touches the workspaces for the first
    /// time. A long-running tracker pays this once.
    pub first_ms: f64,
    /// Every later frame, over all passes (later passes restart at ground truth but keep
    /// the ray table).
    pub steady_ms: Vec<f64>,
    /// Of `steady_ms`, the scene map (region, gate, map building) per frame.
    pub scene_ms: Vec<f64>,
    /// Of `steady_ms`, the registration and the quality per frame.
    pub register_ms: Vec<f64>,
    /// Of the steady frames, those whose pose was estimated from the frame (tracking,
    /// no failed registration): an object that is not found costs less, and says so.
    pub estimated: usize,
}

/// The tracker's step times: per object, and the whole step per frame.
#[derive(Debug, Clone)]
pub struct TrackingTimes {
    /// Per object of the configuration, in its order.
    pub objects: Vec<ObjectTimes>,
    /// The whole step per steady frame: every object, and the end of the frame (the
    /// motion that objects not seen follow).
    pub step_ms: Vec<f64>,
    /// Indices into the steady frames' times (of every object, and of the step) where a
    /// pass after the first starts.
    pub pass_starts: Vec<usize>,
}

/// Prints the rows of [`tracking_ms`]'s times at one image `size`: one per object, and
/// with several, one for the whole step.
pub fn print_tracking(t: &TrackingTimes, size: &str, threads: usize) {
    for o in &t.objects {
        println!(
            "| {size} | {} | {threads} | {} ({}) | {:.2} / {:.2} | {:.2} / {:.2} | {:.2} |",
            o.name,
            o.steady_ms.len(),
            o.estimated,
            percentile(&o.steady_ms, 0.5),
            percentile(&o.steady_ms, 0.99),
            percentile(&o.scene_ms, 0.5),
            percentile(&o.register_ms, 0.5),
            o.first_ms
        );
    }
    if t.objects.len() > 1 {
        println!(
            "| {size} | all {}, the whole step | {threads} | {} | {:.2} / {:.2} | – | – |",
            t.objects.len(),
            t.step_ms.len(),
            percentile(&t.step_ms, 0.5),
            percentile(&t.step_ms, 0.99)
        );
    }
}

/// One frame's times: per object (scene map, registration, estimated), and the step.
type FrameTimes = (Vec<(f64, f64, bool)>, f64);

/// Times the tracker's per-frame step (scene map + registration + quality, per object)
/// on `frames` frames of a dataset from `first_frame`, every object started at its
/// ground-truth pose; frames are decoded beforehand. With a `gap`, the thread sleeps
/// that long before each frame (a live tracker idles between camera frames). Returns
/// the times (ms) per object and frame, over `passes` passes, the start-up frame apart.
pub fn tracking_ms(
    config: &crate::io::tracker_config::TrackerConfig,
    job: &BenchJob,
    first_frame: usize,
    half: bool,
    gap: std::time::Duration,
) -> Result<TrackingTimes> {
    use super::tracking::{LoadedTracker, StepOutput, Workers, load_tracker, track_frame};
    // Frames after an idle gap are tracked as the live tracker tracks them.
    let workers = if gap.is_zero() { Workers::Spin } else { Workers::Sleep };
    let camera = read_camera(&job.camera)?;
    let dataset = TumDataset::open(&job.dataset).with_context(|| format!("opening {}", job.dataset.display()))?;
    let mut loader = FrameLoader::new(camera, half);
    let cam = loader.camera();
    let mut decoded = Vec::new();
    for entry in dataset.frames.iter().skip(first_frame).take(job.frames) {
        let f = loader.load(entry)?;
        decoded.push(Decoded { stamp_ns: f.stamp_ns, rgb: f.rgb.to_vec(), depth: f.depth.to_vec() });
    }
    if decoded.is_empty() {
        bail!("no frames after --first-frame {first_frame}");
    }
    let gt = dataset
        .groundtruth
        .as_ref()
        .context("the tracking benchmark starts at ground truth: groundtruth.txt needed")?;
    let start = gt.at_stamp_ns(decoded[0].stamp_ns).context("no ground truth at the first frame")?;
    // The frames run as in the live tracker (`LiveTracker::start`): on a thread that is
    // itself worker 0 of the pool, so that each frame's work starts on that thread
    // instead of being handed to a pool thread (which, after an idle gap, may wake
    // late). rayon cannot release a thread from a pool it joined: the loop gets a
    // thread of its own. The models load on that pool too.
    let timed = || -> Result<(Vec<FrameTimes>, Vec<usize>)> {
        let (pool, _) = super::dataset::thread_pool_on_this_thread(job.threads, config.pin_threads)?;
        let LoadedTracker { mut tracker, world_from_model, .. } =
            load_tracker(config, &pool, cam.width as usize, cam.height as usize)?;
        let tracker = &mut tracker;
        let mut out = StepOutput::new(tracker.len());
        let mut frames = Vec::new();
        let mut pass_starts = Vec::new();
        for pass in 0..job.passes {
            if pass > 0 {
                pass_starts.push(frames.len());
            }
            for (k, w) in world_from_model.iter().enumerate() {
                tracker.reinitialise(k, &(start.inverse() * w));
            }
            for d in &decoded {
                let frame = RgbdFrame::new(d.stamp_ns, cam, &d.rgb, &d.depth)?;
                if !gap.is_zero() {
                    std::thread::sleep(gap);
                }
                let t0 = std::time::Instant::now();
                track_frame(tracker, &pool, &frame, &mut out, workers);
                let step_ms = t0.elapsed().as_secs_f64() * 1e3;
                let objects = (0..tracker.len())
                    .map(|k| (f64::from(out.build_ms[k]), f64::from(out.register_ms[k]), out.estimates[k].is_fresh()))
                    .collect();
                frames.push((objects, step_ms));
            }
        }
        Ok((frames, pass_starts))
    };
    let (mut frames, pass_starts) = std::thread::scope(|s| {
        s.spawn(timed).join().map_err(|_| anyhow::anyhow!("the tracking benchmark's thread failed"))
    })??;
    if frames.len() < 2 {
        bail!("the tracking benchmark needs at least 2 frames (the first one is timed apart)");
    }
    let (first, _) = frames.remove(0);
    // The start-up frame taken out shifts every later pass's start by one.
    let pass_starts = pass_starts.iter().map(|&start| start - 1).collect();
    let objects = config
        .objects
        .iter()
        .enumerate()
        .map(|(k, o)| ObjectTimes {
            name: o.name.clone(),
            first_ms: first[k].0 + first[k].1,
            steady_ms: frames.iter().map(|(f, _)| f[k].0 + f[k].1).collect(),
            scene_ms: frames.iter().map(|(f, _)| f[k].0).collect(),
            register_ms: frames.iter().map(|(f, _)| f[k].1).collect(),
            estimated: frames.iter().filter(|(f, _)| f[k].2).count(),
        })
        .collect();
    Ok(TrackingTimes { objects, step_ms: frames.iter().map(|f| f.1).collect(), pass_starts })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cpu_model_is_the_first_model_name_line() {
        let text = "processor\t: 0\nvendor_id\t: GenuineIntel\nmodel name\t: Intel(R) Xeon(R) Processor\n\nprocessor\t: 1\nmodel name\t: other\n";
        assert_eq!(cpu_model_in(text).as_deref(), Some("Intel(R) Xeon(R) Processor"));
        assert_eq!(cpu_model_in("processor\t: 0\nmodel name\t:   \n"), None);
        assert_eq!(cpu_model_in(""), None);
    }
}
