//! `mrsmap synth`: synthetic RGB-D sequences with exact ground truth, rendered from a
//! scene file (textured meshes, boxes, a depth sensor's errors, camera paths) into TUM
//! RGB-D folders that every other command reads as it reads the benchmark's.

use super::interrupt::{Interrupted, Stop};
use super::report::progress_bar;
use crate::geometry::{CameraModel, Pose};
use crate::io::camera_file::read_camera;
use crate::io::image::{write_depth16, write_rgb8};
use crate::io::scene_file::{SceneSpec, SequenceSpec, read_scene};
use crate::io::tum::{format_pose, format_stamp, write_trajectory};
use crate::synthetic::scene::{ColorField, add_box};
use crate::synthetic::{Mesh, Pcg32, RenderTarget, clear, draw};
use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What to render.
#[derive(Debug, Clone)]
pub struct SynthJob {
    /// The scene file.
    pub scene: PathBuf,
    /// The folder that receives one folder per sequence.
    pub out: PathBuf,
    /// Only these sequences (all if empty).
    pub sequences: Vec<String>,
    /// Replace sequence folders that exist.
    pub force: bool,
    /// At most this many frames per sequence.
    pub max_frames: Option<usize>,
    /// Stops before the next frame; the frames so far make a complete folder.
    pub stop: Stop,
}

/// One rendered sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedSequence {
    /// Its name.
    pub name: String,
    /// Its folder.
    pub folder: PathBuf,
    /// Frames written.
    pub frames: usize,
}

/// What was rendered.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthSummary {
    /// The sequences, in the scene's order.
    pub sequences: Vec<RenderedSequence>,
    /// Set if a signal stopped the run (the last sequence holds the frames before).
    pub interrupted: Option<Interrupted>,
}

/// The first frame's stamp (s): any fixed value; TUM stamps are Unix times.
const FIRST_STAMP_S: u64 = 1_700_000_000;

/// The longest interval between ground-truth poses (ns).
const GROUND_TRUTH_PERIOD_NS: u64 = 10_000_000;

/// Frames rendered at once (in parallel) between checks for a stop.
const BATCH: usize = 8;

/// Renders the job's sequences.
pub fn run(job: &SynthJob) -> Result<SynthSummary> {
    let scene = read_scene(&job.scene)?;
    let camera = read_camera(&scene.camera).context("the scene's camera")?;
    if camera.is_distorted() {
        bail!(
            "camera file {} has lens distortion: synth renders a pinhole; give the scene a camera file without distortion",
            scene.camera.display()
        );
    }
    for name in &job.sequences {
        if !scene.sequences.iter().any(|s| &s.name == name) {
            let known: Vec<&str> = scene.sequences.iter().map(|s| s.name.as_str()).collect();
            bail!("--sequence {name}: the scene has no such sequence (it has {})", known.join(", "));
        }
    }
    let chosen: Vec<&SequenceSpec> =
        scene.sequences.iter().filter(|s| job.sequences.is_empty() || job.sequences.contains(&s.name)).collect();
    std::fs::create_dir_all(&job.out).with_context(|| format!("creating --out {}", job.out.display()))?;
    for s in &chosen {
        super::outputs::refuse_to_replace(&job.out.join(&s.name), job.force, None)?;
    }
    let world = world_meshes(&scene)?;
    let mut summary = SynthSummary { sequences: Vec::new(), interrupted: None };
    for sequence in chosen {
        let (rendered, interrupted) = render_sequence(job, &scene, camera, &world, sequence)?;
        summary.sequences.push(rendered);
        if interrupted.is_some() {
            summary.interrupted = interrupted;
            break;
        }
    }
    Ok(summary)
}

/// The scene's boxes (one vertex-coloured mesh) and meshes, in the world frame.
fn world_meshes(scene: &SceneSpec) -> Result<Vec<Mesh>> {
    let mut boxes = Mesh::default();
    for b in &scene.boxes {
        let field = ColorField::new(&mut Pcg32::new(b.texture_seed), 12);
        add_box(&mut boxes, b.min, b.size_m, b.step_m, &field);
    }
    let mut world = vec![boxes];
    for m in &scene.meshes {
        let mut mesh = Mesh::load_obj(&m.obj).with_context(|| format!("mesh {:?} of the scene", m.name))?;
        if mesh.triangles.is_empty() {
            bail!("mesh {:?}: {} has no triangles", m.name, m.obj.display());
        }
        mesh.scale(m.scale);
        mesh.transform(&m.world_from_mesh);
        world.push(mesh);
    }
    Ok(world)
}

/// Renders one sequence into `<out>/<name>.partial`, then names it `<out>/<name>`.
fn render_sequence(
    job: &SynthJob,
    scene: &SceneSpec,
    camera: CameraModel,
    world: &[Mesh],
    sequence: &SequenceSpec,
) -> Result<(RenderedSequence, Option<Interrupted>)> {
    let folder = job.out.join(&sequence.name);
    let partial = job.out.join(format!("{}.partial", sequence.name));
    if partial.exists() {
        std::fs::remove_dir_all(&partial).with_context(|| format!("removing the old {}", partial.display()))?;
    }
    for sub in ["rgb", "depth"] {
        std::fs::create_dir_all(partial.join(sub)).with_context(|| format!("creating {}", partial.display()))?;
    }
    let all = (sequence.path.duration_s() * scene.rate_hz).floor() as usize + 1;
    let total = all.min(job.max_frames.unwrap_or(usize::MAX));
    let bar = progress_bar(total as u64, &format!("rendering {}", sequence.name));
    let salt = sequence.name.bytes().fold(scene.seed, |h, b| h.wrapping_mul(0x100_0000_01B3).wrapping_add(b as u64));
    let mut poses: Vec<(u64, Pose)> = Vec::with_capacity(total);
    let mut interrupted = None;
    for start in (0..total).step_by(BATCH) {
        interrupted = job.stop.before_frame(start, Some(total));
        if interrupted.is_some() {
            break;
        }
        let batch: Vec<Result<(u64, Pose)>> = (start..(start + BATCH).min(total))
            .into_par_iter()
            .map(|k| {
                // Whole microseconds, as the TUM files write them.
                let stamp_ns = (FIRST_STAMP_S * 1_000_000 + (k as f64 * 1e6 / scene.rate_hz).round() as u64) * 1000;
                let pose = sequence.path.world_from_camera(k as f64 / scene.rate_hz);
                let mut target = RenderTarget::new(camera);
                clear(&mut target, scene.background);
                for mesh in world {
                    draw(mesh, &pose, &mut target, 0.05);
                }
                scene.sensor.apply(&mut target, &mut Pcg32::new(salt ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)));
                let name = format!("{}.png", format_stamp(stamp_ns));
                write_rgb8(&partial.join("rgb").join(&name), camera.width, camera.height, &target.rgb)?;
                write_depth16(&partial.join("depth").join(&name), camera.width, camera.height, &target.depth)?;
                Ok((stamp_ns, pose))
            })
            .collect();
        for frame in batch {
            poses.push(frame?);
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    write_lists(&partial, job, scene, sequence, &poses, interrupted)?;
    if folder.exists() {
        std::fs::remove_dir_all(&folder).with_context(|| format!("replacing {}", folder.display()))?;
    }
    std::fs::rename(&partial, &folder).with_context(|| format!("renaming to {}", folder.display()))?;
    Ok((RenderedSequence { name: sequence.name.clone(), folder, frames: poses.len() }, interrupted))
}

/// rgb.txt, depth.txt, associations.txt, groundtruth.txt and SOURCE.txt of a rendered
/// sequence (colour and depth share their stamps: the sensor is ideal in time).
fn write_lists(
    folder: &Path,
    job: &SynthJob,
    scene: &SceneSpec,
    sequence: &SequenceSpec,
    poses: &[(u64, Pose)],
    interrupted: Option<Interrupted>,
) -> Result<()> {
    let header = |what: &str| format!("# {what}\n# rendered by mrsmap synth from {}\n", job.scene.display());
    let (mut rgb, mut depth, mut assoc) =
        (header("color images\n# timestamp filename"), header("depth images\n# timestamp filename"), String::new());
    for (stamp_ns, _) in poses {
        let s = format_stamp(*stamp_ns);
        let _ = writeln!(rgb, "{s} rgb/{s}.png");
        let _ = writeln!(depth, "{s} depth/{s}.png");
        let _ = writeln!(assoc, "{s} rgb/{s}.png {s} depth/{s}.png");
    }
    // The poses the frames were rendered at, and between them (and to one period past
    // the last) at least every 10 ms, as motion capture records them: the readers
    // interpolate the ground truth across short gaps only.
    let first_ns = poses.first().map_or(0, |p| p.0);
    let mut gt = Vec::with_capacity(poses.len() * 5);
    for (k, &(stamp_ns, pose)) in poses.iter().enumerate() {
        gt.push((stamp_ns, pose));
        let next_ns = poses.get(k + 1).map_or(stamp_ns + GROUND_TRUTH_PERIOD_NS, |p| p.0);
        let steps = (next_ns - stamp_ns).div_ceil(GROUND_TRUTH_PERIOD_NS);
        for j in 1..=steps {
            let at_ns = stamp_ns + (next_ns - stamp_ns) * j / steps;
            if at_ns < next_ns || k + 1 == poses.len() {
                gt.push((at_ns, sequence.path.world_from_camera((at_ns - first_ns) as f64 * 1e-9)));
            }
        }
    }
    let gt_header = format!(
        "ground truth trajectory (world_from_camera, exact)\nrendered by mrsmap synth from {}",
        job.scene.display()
    );
    write_trajectory(&folder.join("groundtruth.txt"), &gt_header, &gt)?;
    let mut source = format!(
        "Synthetic RGB-D sequence {:?} rendered by `mrsmap synth --scene {}` ({} frames at {} Hz, seed {}).\n\
         Exact ground truth in groundtruth.txt. Sensor: {:?}.\nMeshes (world_from_mesh: tx ty tz qx qy qz qw):\n",
        sequence.name,
        job.scene.display(),
        poses.len(),
        scene.rate_hz,
        scene.seed,
        scene.sensor,
    );
    for m in &scene.meshes {
        let pose = format_pose(&m.world_from_mesh);
        let _ = writeln!(source, "  {} {} scale {}: {pose}", m.name, m.obj.display(), m.scale);
    }
    if let Some(i) = interrupted {
        let _ = writeln!(source, "{i}: the sequence is shorter than the scene's path");
    }
    for (name, text) in [("rgb.txt", rgb), ("depth.txt", depth), ("associations.txt", assoc), ("SOURCE.txt", source)] {
        let path = folder.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
