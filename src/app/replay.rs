//! `mrsmap replay`: the tracker's per-frame step (the one the live process runs) on every
//! frame of an MCAP recording; poses out as MCAP (ROS 2 and Foxglove) and TUM trajectories.
//! The detections a live run applied (recorded with it) are applied again before the
//! same frames.

use super::accuracy::{ObjectAccuracy, Published};
use super::dataset::thread_pool;
use super::interrupt::{Interrupted, Stop};
use super::poses_client::{object_trajectory_header, object_trajectory_path};
use super::read_ahead::read_frame;
use super::replay_detections::RecordedDetections;
use super::report::{both_written, percentile, progress_bar, write_or_rescue};
use super::tracking::{LoadedModels, StepOutput, Workers, load_models, track_frame, tracker_for};
use crate::frame::{OwnedFrame, RayTable};
use crate::geometry::{CameraModel, Pose};
use crate::io::mcap_source::ReadMode;
use crate::io::mcap_write::{DEFAULT_CHUNK_BYTES, McapFile, ObjectPoseRecord, PoseChannels};
use crate::io::recording::{Damage, RecordingReader, RecordingStats, RecordingTopics};
use crate::io::tracker_config::TrackerConfig;
use crate::io::tum::{Trajectory, write_trajectory};
use crate::map::SurfelMap;
use crate::tracking::{ObjectModel, Tracker, TrackingStatus};
use anyhow::{Context, Result, bail};
use std::path::PathBuf;
use std::time::Instant;

/// What to replay.
#[derive(Debug, Clone)]
pub struct ReplayJob {
    /// The recording.
    pub input: PathBuf,
    /// Poses to write (MCAP).
    pub out: Option<PathBuf>,
    /// Replace `out` if it exists.
    pub force: bool,
    /// `object_from_camera` per object (TUM format; suffixed by name for several).
    pub trajectory: Option<PathBuf>,
    /// Topics of the images and calibration.
    pub topics: RecordingTopics,
    /// Camera replacing the recording's calibration.
    pub camera: Option<CameraModel>,
    /// Ground truth of the recording (TUM, `world_from_camera` in the models' mapping
    /// world): the summary gets each object's accuracy.
    pub groundtruth: Option<PathBuf>,
    /// Track every n-th frame only (1: all).
    pub every: usize,
    /// Halve images and intrinsics (QVGA from VGA).
    pub qvga: bool,
    /// Stop after this many frames.
    pub max_frames: Option<usize>,
    /// Stops the replay before its next frame; the poses so far are written and the
    /// MCAP file is finished.
    pub stop: Stop,
}

/// What happened.
#[derive(Debug, Clone)]
pub struct ReplaySummary {
    /// How the file was read.
    pub mode: ReadMode,
    /// The topics read.
    pub topics: RecordingTopics,
    /// Messages and frames read.
    pub stats: RecordingStats,
    /// Frames tracked.
    pub tracked_frames: usize,
    /// Per object: name, frames per status (tracking, lost, initialising, invalid, and
    /// of those tracking the ones held: no good registration, the last good pose kept),
    /// and tracking time per frame (ms).
    pub objects: Vec<(String, [usize; 5], Vec<f64>)>,
    /// Wall-clock seconds of the whole replay (reading, decoding, tracking, writing).
    pub seconds: f64,
    /// Of these, the seconds until the first frame was tracked (opening the recording,
    /// loading the models, reading and tracking the first frame).
    pub startup_seconds: Option<f64>,
    /// Where the recording was damaged (and could not be read further).
    pub damage: Option<Damage>,
    /// Damaged chunks that were skipped (indexed reading).
    pub skipped_chunks: Vec<String>,
    /// Set if the replay was stopped before the recording's end.
    pub interrupted: Option<Interrupted>,
    /// Per object, its accuracy against `ReplayJob::groundtruth` (empty without it).
    pub accuracy: Vec<ObjectAccuracy>,
    /// The model of the published covariances.
    pub covariance: crate::tracking::CovarianceModel,
    /// Detections recorded with the live run: applied again, in the recording, and
    /// unreadable.
    pub detections: (usize, usize, usize),
}

/// Replays the recording through the tracker.
pub fn run(config: &TrackerConfig, job: &ReplayJob) -> Result<ReplaySummary> {
    if job.every == 0 {
        bail!("--every must be at least 1");
    }
    let out = match &job.out {
        Some(out) => {
            super::outputs::refuse_to_replace(out, job.force, None)?;
            // (The command line checks every output against every input before; this
            // guards the library's callers. A missing input is reported by the reader,
            // naming it.)
            if super::outputs::same_file(out, &job.input) {
                bail!("--out {} is the input recording", out.display());
            }
            Some(crate::io::atomic::file_destination(out).with_context(|| format!("--out {}", out.display()))?)
        }
        None => None,
    };
    // Read before the replay: a bad file is reported before the work.
    let groundtruth = job
        .groundtruth
        .as_deref()
        .map(|p| Trajectory::read(p).with_context(|| format!("--groundtruth {}", p.display())))
        .transpose()?;
    let started = Instant::now();
    let mut reader = RecordingReader::open(&job.input, job.topics.clone(), job.camera)?;
    let depth_count = reader.depth_count();
    let names: Vec<String> = config.objects.iter().map(|o| o.name.clone()).collect();
    let detections = RecordedDetections::read(&job.input, &names)?;
    let pool = thread_pool(config.threads)?;
    // The first frame (which sizes the tracker) is read, and its camera's rays computed,
    // while the models load.
    let (models, (first, rays)) = pool.install(|| {
        rayon::join(
            || load_models(config),
            || {
                let first = read_frame(&mut reader, job.qvga, OwnedFrame::default());
                let rays = first.as_ref().ok().and_then(|f| f.as_ref()?.camera).and_then(|camera| {
                    let mut rays = RayTable::with_capacity(camera.width as usize * camera.height as usize);
                    rays.ensure(&camera).ok().map(|()| rays)
                });
                (first, rays)
            },
        )
    });
    let LoadedModels { objects: models, world_from_model } = models?;
    for warning in super::tracker_check::start_pose_warnings(config, &models) {
        eprintln!("warning: {warning}");
    }
    // Written next to the target and renamed when finished, also after an error, so
    // the poses computed before it are kept.
    let partial = out.as_deref().map(crate::io::atomic::partial_path);
    let maps: Vec<&SurfelMap> = models.iter().map(|m| &m.map).collect();
    let mut output = partial.as_deref().map(|p| create_output(p, &names, &maps)).transpose()?;
    let mut state = Replay {
        models,
        rays,
        tracker: None,
        out: StepOutput::new(names.len()),
        statuses: vec![[0; 5]; names.len()],
        track_ms: vec![Vec::new(); names.len()],
        tracked: vec![Vec::new(); names.len()],
        published: groundtruth.as_ref().map(|_| vec![Vec::new(); names.len()]),
        frames: 0,
        first_tracked: None,
        interrupted: None,
        detections,
        detections_applied: 0,
    };
    let bar = progress_bar(depth_count.unwrap_or(0), "replaying");
    let result = state.replay(config, job, (&mut reader, first), &pool, &names, output.as_mut(), &bar);
    if let Some(i) = &mut state.interrupted {
        i.of = depth_count.map(|n| n as usize);
    }
    bar.finish_and_clear();
    // Every output is tried whatever became of the others (a full disk): the poses
    // tracked so far reach the trajectories even when the MCAP output failed.
    let mut written = result;
    if let (Some((file, _)), Some(partial), Some(out)) = (output, &partial, &out) {
        let finished = file
            .finish()
            .map_err(anyhow::Error::from)
            .and_then(|()| Ok(std::fs::rename(partial, out)?))
            .with_context(|| format!("finishing {} (what was written is kept in it)", partial.display()));
        written = both_written(written, finished);
    }
    if let Some(path) = &job.trajectory {
        let source = format!("recording {}", job.input.display());
        for (k, name) in names.iter().enumerate() {
            let path = object_trajectory_path(path, name, names.len());
            let header = object_trajectory_header("replay", name, &source, state.interrupted);
            let this = write_or_rescue(&path, |p| Ok(write_trajectory(p, &header, &state.tracked[k])?));
            written = both_written(written, this);
        }
    }
    written?;
    let accuracy = groundtruth.map_or_else(Vec::new, |gt| state.accuracy(&gt, &world_from_model));
    Ok(ReplaySummary {
        mode: reader.mode(),
        topics: reader.topics().clone(),
        stats: reader.stats(),
        tracked_frames: state.frames,
        objects: names.into_iter().zip(state.statuses).zip(state.track_ms).map(|((n, s), t)| (n, s, t)).collect(),
        seconds: started.elapsed().as_secs_f64(),
        startup_seconds: state.first_tracked.map(|t| (t - started).as_secs_f64()),
        damage: reader.damage().cloned(),
        skipped_chunks: reader.skipped_chunks().to_vec(),
        interrupted: state.interrupted,
        accuracy,
        covariance: config.params.covariance,
        detections: (state.detections_applied, state.detections.len(), state.detections.unreadable),
    })
}

/// The MCAP file of the poses, created at `partial` (renamed when finished), with the
/// objects' `models`.
fn create_output(
    partial: &std::path::Path,
    names: &[String],
    models: &[&SurfelMap],
) -> Result<(McapFile, PoseChannels)> {
    let mut file = McapFile::create(partial, mcap::Compression::Zstd, DEFAULT_CHUNK_BYTES)
        .with_context(|| format!("creating {}", partial.display()))?;
    let channels = PoseChannels::add(&mut file, names, models)?;
    Ok((file, channels))
}

struct Replay {
    /// The loaded models, moved into the tracker when the first frame sizes it.
    models: Vec<ObjectModel>,
    /// The first frame's rays, computed while the models loaded; moved into the tracker.
    rays: Option<RayTable>,
    tracker: Option<Tracker>,
    out: StepOutput,
    statuses: Vec<[usize; 5]>,
    track_ms: Vec<Vec<f64>>,
    tracked: Vec<Vec<(u64, Pose)>>,
    /// With ground truth, per object: its fresh poses as published (frame index among
    /// those tracked, stamp, pose, covariance).
    published: Option<Vec<Vec<Published>>>,
    frames: usize,
    /// When the first frame had been tracked.
    first_tracked: Option<Instant>,
    interrupted: Option<Interrupted>,
    /// The recording's detections, applied before their frames.
    detections: RecordedDetections,
    detections_applied: usize,
}

impl Replay {
    /// Each object's accuracy against the ground truth, through its model's
    /// `world_from_model` (none without the poses kept for it).
    fn accuracy(&self, gt: &Trajectory, world_from_model: &[Pose]) -> Vec<ObjectAccuracy> {
        let Some(published) = &self.published else { return Vec::new() };
        let at = |stamp_ns: u64| gt.at_stamp_ns(stamp_ns);
        published.iter().zip(world_from_model).map(|(p, w)| ObjectAccuracy::of(p, at, w)).collect()
    }

    #[allow(clippy::too_many_arguments)]
    fn replay(
        &mut self,
        config: &TrackerConfig,
        job: &ReplayJob,
        (reader, first): (&mut RecordingReader, Result<Option<OwnedFrame>>),
        pool: &rayon::ThreadPool,
        names: &[String],
        mut output: Option<&mut (McapFile, PoseChannels)>,
        bar: &indicatif::ProgressBar,
    ) -> Result<()> {
        let mut index = 0usize;
        let mut records = Vec::with_capacity(names.len());
        let (mut next, mut spare) = (first, OwnedFrame::default());
        while let Some(owned) = next? {
            self.interrupted = job.stop.before_frame(index, None);
            if self.interrupted.is_some() {
                break;
            }
            bar.inc(1);
            index += 1;
            let to_track = (index - 1).is_multiple_of(job.every);
            if to_track && job.max_frames.is_some_and(|m| self.frames >= m) {
                break;
            }
            let Some(frame) = owned.view().filter(|_| to_track) else {
                next = read_frame(reader, job.qvga, owned);
                continue;
            };
            let tracker = match &mut self.tracker {
                Some(t) => t,
                // Sized by the first frame: the recording's resolution.
                None => {
                    let models = std::mem::take(&mut self.models);
                    let tracker = self.tracker.insert(tracker_for(config, models, frame.width(), frame.height())?);
                    if let Some(rays) = self.rays.take() {
                        tracker.adopt_rays(rays);
                    }
                    tracker
                }
            };
            // As the live tracker did: detections re-initialise their objects first.
            for &(_, k, camera_from_object) in self.detections.due(frame.stamp_ns) {
                tracker.reinitialise(k, &camera_from_object);
                self.detections_applied += 1;
                if let Some((file, channels)) = output.as_deref_mut() {
                    channels.write_detection(file, k, frame.stamp_ns, &camera_from_object)?;
                }
            }
            // The next frame is read and decoded beside the step, on the same workers.
            let out = &mut self.out;
            let spare_buffers = std::mem::take(&mut spare);
            let ((), following) = pool.install(|| {
                rayon::join(
                    || track_frame(tracker, pool, &frame, out, Workers::Spin),
                    || read_frame(reader, job.qvga, spare_buffers),
                )
            });
            self.first_tracked.get_or_insert_with(Instant::now);
            let index = self.frames;
            self.frames += 1;
            records.clear();
            for (k, name) in names.iter().enumerate() {
                let e = &self.out.estimates[k];
                self.statuses[k][e.status as usize] += 1;
                self.statuses[k][4] += usize::from(e.is_held());
                if e.status != TrackingStatus::InvalidFrame {
                    self.track_ms[k].push(f64::from(self.out.build_ms[k] + self.out.register_ms[k]));
                }
                if e.is_fresh() {
                    self.tracked[k].push((frame.stamp_ns, e.camera_from_object.inverse()));
                    if let Some(p) = &mut self.published {
                        p[k].push((index, frame.stamp_ns, e.camera_from_object, e.covariance_ros));
                    }
                    records.push(ObjectPoseRecord {
                        object: k,
                        name,
                        camera_from_object: e.camera_from_object,
                        covariance_ros: e.covariance_ros,
                    });
                }
            }
            if let Some((file, channels)) = output.as_deref_mut() {
                channels.write(file, frame.stamp_ns, &records)?;
            }
            spare = owned;
            next = following;
        }
        Ok(())
    }
}

/// Prints the summary.
pub fn print_summary(s: &ReplaySummary) {
    let mode = match s.mode {
        ReadMode::Indexed => "indexed",
        ReadMode::Streamed => "streamed (no index)",
    };
    println!(
        "read {} colour, {} depth, {} calibration messages ({mode}); {} frames paired, {} images unpaired; {} tracked",
        s.stats.color, s.stats.depth, s.stats.camera_info, s.stats.frames, s.stats.unpaired, s.tracked_frames
    );
    for (k, (name, [t, l, i, v, h], ms)) in s.objects.iter().enumerate() {
        println!("{name}: {t} frames tracking ({h} held), {l} lost, {i} initialising, {v} invalid");
        if !ms.is_empty() {
            println!(
                "  tracking time per frame: median {:.2} ms, p99 {:.2} ms",
                percentile(ms, 0.5),
                percentile(ms, 0.99)
            );
        }
        match s.accuracy.get(k) {
            Some(a) if a.compared == 0 && t > h => {
                println!(
                    "  warning: the ground truth has no pose within 0.05 s of a tracked frame's stamp (is it this recording's?)"
                );
            }
            Some(a) => a.print(s.covariance),
            None => {}
        }
    }
    if s.tracked_frames > 0 {
        println!(
            "replay: {:.2} s, {:.1} frames/s end to end (reading, decoding, tracking, writing)",
            s.seconds,
            s.tracked_frames as f64 / s.seconds
        );
        // A long recording's rate: its start-up is paid once.
        if let Some(startup) = s.startup_seconds.filter(|_| s.tracked_frames > 1) {
            println!(
                "  after the first frame: {:.1} frames/s (start-up, model loading and the first frame took {:.0} ms)",
                (s.tracked_frames - 1) as f64 / (s.seconds - startup),
                startup * 1e3
            );
        }
    }
    let (applied, recorded, unreadable) = s.detections;
    if recorded + unreadable > 0 {
        println!("detections recorded with the live run: {applied} of {recorded} applied again before their frames");
    }
    if unreadable > 0 {
        println!("warning: {unreadable} detection messages could not be decoded (skipped)");
    }
    // A recording without a summary is streamed: a topic it lacks shows only here.
    let images = [
        ("colour", "--color-topic", &s.topics.color, s.stats.color),
        ("depth", "--depth-topic", &s.topics.depth, s.stats.depth),
    ];
    for (what, flag, topic, messages) in images {
        if messages == 0 && s.damage.as_ref().is_none_or(|d| d.messages_before > 0) {
            println!("warning: no message on the {what} topic {topic} (named by {flag}): no frame could be paired");
        }
    }
    for chunk in &s.skipped_chunks {
        println!("warning: the recording is damaged: {chunk}; its frames were skipped, the rest replayed");
    }
    if let Some(d) = &s.damage {
        println!(
            "warning: the recording is damaged after {} messages ({}); replayed up to the damage",
            d.messages_before, d.reason
        );
    }
}
