//! `mrsmap map`: key-view SLAM over a TUM RGB-D dataset, fused into a model file.

use super::dataset::{initial_pose, install_spinning, thread_pool};
use super::interrupt::{Interrupted, Stop};
use super::report::{both_written, percentile, progress_bar, write_or_rescue};
use crate::eval::{ErrorStats, align_poses, associate, ate_translation};
use crate::geometry::Pose;
use crate::io::camera_file::read_camera;
use crate::io::frames::{FrameLoader, LoadError};
use crate::io::image::ImageError;
use crate::io::object_file::{ObjectSpec, read_object};
use crate::io::tum::{DatasetFrame, Trajectory, TumDataset, format_stamp, write_trajectory};
use crate::model::{FORMAT_VERSION, Model, ModelHeader, ModelSource, RootStats, save};
use crate::slam::{EdgeKind, Fused, LoopOutcome, Slam, SlamCounters, SlamParams, TrackStatus};
use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// What to run.
#[derive(Debug, Clone)]
pub struct MapJob {
    /// Dataset folder (TUM layout).
    pub dataset: PathBuf,
    /// Camera file.
    pub camera: PathBuf,
    /// Object description (volume of interest); the whole scene without it.
    pub object: Option<PathBuf>,
    /// Model file to write.
    pub out: Option<PathBuf>,
    /// Overwrite an existing model file.
    pub force: bool,
    /// Trajectory to write (TUM format, every frame).
    pub trajectory: Option<PathBuf>,
    /// Worker threads (default: all cores).
    pub threads: Option<usize>,
    /// Use at most this many frames (from the first).
    pub max_frames: Option<usize>,
    /// Algorithm parameters.
    pub params: SlamParams,
    /// Stops the frame loop before its next frame; the key views so far are optimised
    /// and fused, and the outputs written.
    pub stop: Stop,
}

/// Per-frame times of the SLAM stages (ms).
#[derive(Debug, Clone, Default)]
pub struct StageTimes {
    /// Map building.
    pub build: Vec<f64>,
    /// Registration to the reference key view.
    pub track: Vec<f64>,
    /// Key-view creation or reference switch (including the matching scores).
    pub key_views: Vec<f64>,
    /// The randomised loop-closure attempt.
    pub loop_closure: Vec<f64>,
    /// One pose-graph step.
    pub graph: Vec<f64>,
    /// All stages of a frame.
    pub total: Vec<f64>,
}

/// What happened.
#[derive(Debug, Clone)]
pub struct MapSummary {
    /// SLAM counters.
    pub counters: SlamCounters,
    /// Frames that could not be read or turned into a map.
    pub skipped: usize,
    /// Key views.
    pub key_views: usize,
    /// Edges by kind: key view, loop closure.
    pub edges: (usize, usize),
    /// Per-stage times.
    pub times: StageTimes,
    /// Final optimisation: time (ms) including the exhaustive pair check and edge refinement.
    pub finish_ms: f64,
    /// Fusion time (ms).
    pub fuse_ms: f64,
    /// The fused model, if one was written.
    pub model: Option<ModelHeader>,
    /// Where it was written: `out`, or beside it if an interrupted run would have
    /// replaced an existing model (`<name>.interrupted.mrsm`).
    pub model_path: Option<PathBuf>,
    /// Usable surfels per level of the model, finest first.
    pub model_surfels: Vec<usize>,
    /// ATE against ground truth, if the dataset has it.
    pub ate: Option<ErrorStats>,
    /// Warnings worth repeating at the end.
    pub warnings: Vec<String>,
    /// Set if the frame loop was stopped before its last frame.
    pub interrupted: Option<Interrupted>,
}

/// What the frame loop leaves behind.
struct FrameLoop {
    times: StageTimes,
    skipped: usize,
    notes: String,
    interrupted: Option<Interrupted>,
}

/// Runs SLAM, writes the trajectory and the model, and returns a summary.
pub fn run(job: &MapJob) -> Result<MapSummary> {
    if job.out.is_none() && job.trajectory.is_none() {
        bail!("nothing to write: give --out (the model) and/or --trajectory");
    }
    if let Some(out) = &job.out {
        let note = "the old model is kept until the new one is complete";
        super::outputs::refuse_to_replace(out, job.force, Some(note))?;
    }
    let camera = read_camera(&job.camera)?;
    let object = job.object.as_ref().map(|p| read_object(p)).transpose()?;
    let dataset =
        TumDataset::open(&job.dataset).with_context(|| format!("opening dataset {}", job.dataset.display()))?;
    let mut frames = dataset.frames.clone();
    if let Some(n) = job.max_frames {
        frames.truncate(n);
    }
    if frames.is_empty() {
        bail!("no frames to process");
    }
    let mut notes = String::new();
    let start = initial_pose(&dataset, frames[0].depth_stamp_ns, &mut notes);
    let mut slam = Slam::new(job.params, camera.width as usize, camera.height as usize, start)?;
    let pool = thread_pool(job.threads)?;
    let mut done = process_frames(job, FrameLoader::new(camera, false), &frames, &mut slam, &pool)?;
    notes.push_str(&done.notes);
    let t = Instant::now();
    let finish = slam.finish();
    let finish_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut warnings = Vec::new();
    if let Err(e) = &finish {
        let w = format!("final optimisation stopped early: {e}; poses are the last good estimate");
        let _ = writeln!(notes, "{w}");
        warnings.push(w);
    }
    if let Some(alignment) = ground_truth_alignment(&dataset, &slam) {
        slam.change_world(&alignment.0);
        let _ = writeln!(
            notes,
            "world frame: the ground truth's, by rigid alignment of the whole trajectory, positions and orientations ({} poses; the first pose alone is only as good as the ground truth at the first frame)",
            alignment.1
        );
    }
    let trajectory: Vec<(u64, Pose)> = slam.trajectory().iter().map(|(s, p, _)| (*s, *p)).collect();
    let mut trajectory_written = Ok(());
    if let Some(path) = &job.trajectory {
        let header = format!(
            "mrsmap map {}: world_from_camera, stamped with depth timestamps\ndataset {} camera {}\n{}",
            env!("CARGO_PKG_VERSION"),
            job.dataset.display(),
            job.camera.display(),
            notes.trim_end()
        );
        // A trajectory that cannot be written does not stop the model (it is said at the end).
        trajectory_written = write_or_rescue(path, |p| Ok(write_trajectory(p, &header, &trajectory)?));
    }
    let count = |kind| slam.graph.edges.iter().filter(|e| e.kind == kind).count();
    let mut summary = MapSummary {
        counters: slam.counters(),
        skipped: done.skipped,
        key_views: slam.key_views.len(),
        edges: (count(EdgeKind::KeyView), count(EdgeKind::LoopClosure)),
        times: std::mem::take(&mut done.times),
        finish_ms,
        fuse_ms: 0.0,
        model: None,
        model_path: None,
        model_surfels: Vec::new(),
        ate: ate_against(&dataset, &trajectory),
        warnings,
        interrupted: done.interrupted,
    };
    let written = trajectory_written.is_ok() && job.trajectory.is_some();
    let model_written = write_model(job, &mut slam, object.as_ref(), (&trajectory, written), &pool, &mut summary);
    // Both said when both failed (each may have been rescued into the temporary folder).
    both_written(model_written, trajectory_written)?;
    Ok(summary)
}

/// Fuses the key views into the model and writes it to `out` (beside it, if an
/// interrupted run would replace a model), rescued into the temporary folder if that
/// fails. Nothing without `--out`.
fn write_model(
    job: &MapJob,
    slam: &mut Slam,
    object: Option<&ObjectSpec>,
    (trajectory, trajectory_written): (&[(u64, Pose)], bool),
    pool: &rayon::ThreadPool,
    summary: &mut MapSummary,
) -> Result<()> {
    let Some(out) = job.out.as_deref() else { return Ok(()) };
    let t = Instant::now();
    let fused = pool.install(|| slam.fuse(object.map(|o| &o.volume))).with_context(|| {
        if trajectory_written {
            "fusing the key views into a model (the trajectory was written)"
        } else {
            "fusing the key views into a model"
        }
    })?;
    summary.fuse_ms = t.elapsed().as_secs_f64() * 1e3;
    if let (Some(object), Some(volume)) = (object, &fused.volume)
        && let Some(tilt) = object.volume.support_tilt_rad(volume).map(f64::to_degrees)
        && tilt > SUPPORT_TILT_WARNING_DEG
    {
        summary.warnings.push(format!(
            "the support plane was fitted {tilt:.1}° from the plane of the footprint's corners: the object's frame is tilted by as much and its volume may cut the object or keep the support; map from views that see more of the support surface, or check the corners' heights"
        ));
    }
    let header = model_header(job, object, &fused, &frames_span(trajectory), slam.key_views.len());
    summary.model_surfels = fused.map.usable_surfels_per_level().iter().copied().take(fused.map.num_levels()).collect();
    let model = Model { header, map: fused.map };
    // An interrupted run never replaces a model that exists (even with --force).
    let path = match summary.interrupted {
        Some(_) if out.exists() => out.with_extension("interrupted.mrsm"),
        _ => out.to_path_buf(),
    };
    write_or_rescue(&path, |p| Ok(save(p, &model)?))?;
    summary.model = Some(model.header);
    summary.model_path = Some(path);
    Ok(())
}

/// Every frame through the five SLAM stages, each timed.
fn process_frames(
    job: &MapJob,
    mut loader: FrameLoader,
    frames: &[DatasetFrame],
    slam: &mut Slam,
    pool: &rayon::ThreadPool,
) -> Result<FrameLoop> {
    let bar = progress_bar(frames.len() as u64, "mapping");
    let mut out = FrameLoop { times: StageTimes::default(), skipped: 0, notes: String::new(), interrupted: None };
    for (index, entry) in frames.iter().enumerate() {
        if let Some(interrupted) = job.stop.before_frame(index, Some(frames.len())) {
            let _ = writeln!(out.notes, "{interrupted}");
            out.interrupted = Some(interrupted);
            break;
        }
        bar.inc(1);
        let stamp = format_stamp(entry.depth_stamp_ns);
        let frame = match pool.install(|| loader.load(entry)) {
            Ok(f) => f,
            Err(e) => {
                if slam.key_views.is_empty() && matches!(e, LoadError::Image(ImageError::Size { .. })) {
                    bail!("{e}\n(does the camera file {} match this dataset?)", job.camera.display());
                }
                bar.suspend(|| eprintln!("warning: skipping frame {stamp}: {e}"));
                let _ = writeln!(out.notes, "skipped {stamp}: {e}");
                out.skipped += 1;
                continue;
            }
        };
        let t0 = Instant::now();
        if let Err(e) = install_spinning(pool, || slam.build(&frame)) {
            bar.suspend(|| eprintln!("warning: skipping frame {stamp}: {e}"));
            let _ = writeln!(out.notes, "skipped {stamp}: {e}");
            out.skipped += 1;
            continue;
        }
        let t1 = Instant::now();
        let status = install_spinning(pool, || slam.track(&frame));
        let t2 = Instant::now();
        slam.update_key_views(&frame);
        let t3 = Instant::now();
        let outcome = install_spinning(pool, || slam.close_loop());
        let t4 = Instant::now();
        let graph_error = slam.optimize_step();
        let t5 = Instant::now();
        let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
        let t = &mut out.times;
        for (v, (a, b)) in [
            (&mut t.build, (t0, t1)),
            (&mut t.track, (t1, t2)),
            (&mut t.key_views, (t2, t3)),
            (&mut t.loop_closure, (t3, t4)),
            (&mut t.graph, (t4, t5)),
            (&mut t.total, (t0, t5)),
        ] {
            v.push(ms(a, b));
        }
        if let TrackStatus::Lost(e) = status {
            bar.suspend(|| eprintln!("warning: frame {stamp}: tracking failed ({e}); pose held"));
            let _ = writeln!(out.notes, "tracking failed at {stamp}: {e}; pose held");
        }
        if let Some(e) = graph_error {
            let _ = writeln!(out.notes, "graph step at {stamp} not taken: {e}");
        }
        if matches!(outcome, LoopOutcome::Accepted { .. }) {
            bar.set_message(format!("{} kv {} lc", slam.key_views.len(), slam.counters().loops_accepted));
        }
    }
    bar.finish_and_clear();
    if slam.key_views.is_empty() {
        if let Some(i) = out.interrupted {
            bail!("{i}: no key view yet, nothing written");
        }
        bail!("no frame of {} could be processed", job.dataset.display());
    }
    Ok(out)
}

/// First and last stamp and the frame count.
fn frames_span(trajectory: &[(u64, Pose)]) -> (u64, u64, usize) {
    let first = trajectory.first().map_or(0, |t| t.0);
    let last = trajectory.last().map_or(0, |t| t.0);
    (first, last, trajectory.len())
}

fn model_header(
    job: &MapJob,
    object: Option<&ObjectSpec>,
    fused: &Fused,
    span: &(u64, u64, usize),
    key_views: usize,
) -> ModelHeader {
    let name = match (object, &job.out) {
        (Some(o), _) => o.name.clone(),
        (None, Some(out)) => out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        (None, None) => String::new(),
    };
    let p = fused.world_from_model;
    let (t, q) = (p.translation.vector, p.rotation.quaternion());
    ModelHeader {
        name,
        frame: if fused.volume.is_some() { "object" } else { "world" }.into(),
        map_params: fused.map.params().into(),
        volume: fused.volume.clone(),
        world_from_model: [t.x, t.y, t.z, q.i, q.j, q.k, q.w],
        source: ModelSource {
            dataset: job.dataset.display().to_string(),
            camera: job.camera.display().to_string(),
            frames: span.2 as u32,
            first_stamp_ns: span.0,
            last_stamp_ns: span.1,
            key_views: key_views as u32,
            created_by: format!("mrsmap {} (model format {FORMAT_VERSION})", env!("CARGO_PKG_VERSION")),
        },
        root: RootStats::of(&fused.map),
        nodes: fused.map.nodes().len() as u32,
        surfels: fused.map.surfels().len() as u32,
    }
}

/// A fitted support plane this far (degrees) from the footprint's plane is reported.
const SUPPORT_TILT_WARNING_DEG: f64 = 10.0;

/// How far ahead of the camera the ground-truth alignment weighs orientations: the
/// working distance of the objects the tool maps (the teddy stands ~1 m away), so that
/// the alignment puts the points the camera saw where the ground truth says they are.
const ALIGNMENT_LEVER_M: f64 = 1.0;

/// The rigid transform that best aligns the SLAM trajectory with the ground truth, whole
/// poses (positions and orientations, see [`align_poses`]), and the number of poses it
/// rests on, when the dataset has ground truth.
fn ground_truth_alignment(dataset: &TumDataset, slam: &Slam) -> Option<(Pose, usize)> {
    let gt = dataset.groundtruth.as_ref()?;
    let trajectory = slam.trajectory();
    let est = Trajectory {
        stamps: trajectory.iter().map(|(t, _, _)| *t as f64 * 1e-9).collect(),
        poses: trajectory.iter().map(|(_, p, _)| *p).collect(),
    };
    let (reference, estimate) = associate(gt, &est, 0.02).ok()?;
    if reference.is_empty() {
        return None;
    }
    Some((align_poses(&estimate, &reference, ALIGNMENT_LEVER_M), reference.len()))
}

fn ate_against(dataset: &TumDataset, trajectory: &[(u64, Pose)]) -> Option<ErrorStats> {
    let gt = dataset.groundtruth.as_ref()?;
    let est = Trajectory {
        stamps: trajectory.iter().map(|(t, _)| *t as f64 * 1e-9).collect(),
        poses: trajectory.iter().map(|(_, p)| *p).collect(),
    };
    let (r, e) = associate(gt, &est, 0.02).ok()?;
    let errors = ate_translation(&r, &e).ok()?;
    (!errors.is_empty()).then(|| ErrorStats::of(&errors))
}

/// Prints the summary.
pub fn print_summary(job: &MapJob, s: &MapSummary) {
    let c = &s.counters;
    println!(
        "mapping: {} frames, {} lost (pose held), {} skipped; {} key views, {} edges ({} key-view, {} loop closure)",
        c.frames,
        c.lost,
        s.skipped,
        s.key_views,
        s.edges.0 + s.edges.1,
        s.edges.0,
        s.edges.1
    );
    println!(
        "  loop closures: {} attempts, {} accepted, {} rejected by the matching likelihood, {} registrations failed",
        c.loop_attempts, c.loops_accepted, c.loops_rejected, c.loops_failed
    );
    if c.graph_failures > 0 {
        println!("  graph steps not taken: {} (the graph was left unchanged)", c.graph_failures);
    }
    let t = &s.times;
    println!("  time per frame (ms)   median     p99");
    for (name, v) in [
        ("map building", &t.build),
        ("tracking", &t.track),
        ("key views", &t.key_views),
        ("loop closure", &t.loop_closure),
        ("graph step", &t.graph),
        ("total", &t.total),
    ] {
        println!("    {name:<16} {:8.2} {:8.2}", percentile(v, 0.5), percentile(v, 0.99));
    }
    println!("  final optimisation (pair check, edge refinement, convergence): {:.0} ms", s.finish_ms);
    if let Some(path) = &job.trajectory {
        println!("  trajectory → {}", path.display());
    }
    if let Some(a) = &s.ate {
        println!(
            "  ATE vs ground truth ({} poses): RMSE {:.2} mm, median {:.2} mm, max {:.2} mm",
            a.count,
            a.rmse * 1e3,
            a.median * 1e3,
            a.max * 1e3
        );
    }
    if let (Some(h), Some(out)) = (&s.model, &s.model_path) {
        println!(
            "  model '{}' ({} frame): {} nodes, {} surfels, usable surfels per level (finest first) {:?}; fused in {:.0} ms → {}",
            h.name,
            h.frame,
            h.nodes,
            h.surfels,
            s.model_surfels,
            s.fuse_ms,
            out.display()
        );
    }
    for w in &s.warnings {
        println!("  warning: {w}");
    }
}
