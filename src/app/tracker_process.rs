//! `mrsmap track`: the robot-side tracker process. RGB-D frames arrive over iceoryx2
//! shared memory; each object's pose is written to the pose blackboard. Everything is
//! allocated at start-up; the loop blocks on the camera's event (no polling), takes the
//! newest frame, runs the tracker step and publishes, without allocating.
//!
//! It waits on the camera's listener directly rather than on a `WaitSet`: iceoryx2
//! 0.10's `WaitSet` allocates two small vectors on every wake-up (measured), the
//! listener's timed wait none. The wait times out every 250 ms to notice signals and an
//! idle camera.

use super::detections::{DetectionCounts, DetectionInbox};
use super::recorder::{RecordOptions, RecordStats, Recorder};
use super::report::{RECENT_SAMPLES, log_line, percentile, push_recent};
use super::tracking::{StepOutput, Workers, invalid_frame, load_tracker, pose_message, track_frame};
use crate::io::ipc::{self, FrameSize, Ipc, IpcError, now_ns};
use crate::io::tracker_config::TrackerConfig;
use crate::io::wire::{ObjectPose, RgbdFrameQvga, RgbdFrameVga, WireFrame};
use crate::map::SurfelMap;
use crate::tracking::Tracker;
use anyhow::Result;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::subscriber::Subscriber;
use std::time::{Duration, Instant};

/// When to stop (besides SIGINT/SIGTERM).
#[derive(Debug, Clone, Copy, Default)]
pub struct RunLimits {
    /// Stop after this many frames.
    pub max_frames: Option<u64>,
    /// Stop after this long without a frame.
    pub idle_timeout: Option<Duration>,
}

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// SIGINT or SIGTERM.
    Signal,
    /// `max_frames` reached.
    FrameLimit,
    /// No frame within `idle_timeout`.
    Idle,
}

/// What a run did.
#[derive(Debug)]
pub struct RunSummary {
    /// Frames processed.
    pub frames: u64,
    /// Frames refused (wrong size or version, bad intrinsics, no depth).
    pub invalid_frames: u64,
    /// Frames that were overwritten by newer ones before the tracker took them.
    pub skipped_frames: u64,
    /// Why it stopped.
    pub stop: StopReason,
    /// Tracking time per frame (ms), all objects together, the last ≤ `RECENT_SAMPLES` frames.
    pub track_ms: Vec<f64>,
    /// Driver send → poses published (ms), same frames.
    pub latency_ms: Vec<f64>,
    /// Why the recording (`--record`) failed, if it did; the run itself went on.
    pub recording_error: Option<anyhow::Error>,
    /// What became of the detections received.
    pub detections: DetectionCounts,
}

/// What the observer sees after each frame (tests use it to arm counters).
#[derive(Debug)]
pub struct FrameEvent<'a> {
    /// Frames processed so far, this one included.
    pub frames: u64,
    /// The frame was refused.
    pub invalid: bool,
    /// The estimates and timings.
    pub output: &'a StepOutput,
}

/// A running tracker for frames of type `F`.
pub struct LiveTracker<F: WireFrame> {
    node: Node<Ipc>,
    listener: Listener<Ipc>,
    core: Core<F>,
    /// The frame and pose services, for the log.
    frames_name: String,
    /// The frame service of the other image size on the same camera (for diagnostics).
    other_size_name: String,
    poses_name: String,
    /// Where the worker threads run (said in the log).
    placement: super::affinity::Placement,
}

/// Creates (or reopens) the pose blackboard `name` and becomes its writer
/// ([`ipc::publish_poses`]). While clients keep an earlier tracker's blackboard that
/// cannot be written (see [`ipc::PosesKept`]), waits for them to let go.
fn publish_poses(node: &Node<Ipc>, name: &str, initial: &[ObjectPose]) -> Result<ipc::PosePorts> {
    let mut said = None;
    loop {
        let why = match ipc::publish_poses(node, name, initial)? {
            Ok(ports) => return Ok(ports),
            Err(why) => why,
        };
        if said != Some(why) {
            log_line(format_args!(
                "tracker: the pose blackboard {name} is kept by its clients, and {why}; waiting for them to let go \
                 (`mrsmap poses` does by itself; restart other clients)"
            ));
            said = Some(why);
        }
        if node.wait(Duration::from_millis(200)).is_err() {
            anyhow::bail!(
                "stopped by a signal while waiting for the clients of {name} to let go of an earlier tracker's poses"
            );
        }
    }
}

/// The part of the process the loop changes (apart from the listener the WaitSet holds).
struct Core<F: WireFrame> {
    tracker: Tracker,
    pool: rayon::ThreadPool,
    out: StepOutput,
    names: Vec<String>,
    subscriber: Subscriber<Ipc, F, ()>,
    poses: ipc::PosePorts,
    notifier: Notifier<Ipc>,
    detections: DetectionInbox,
    track_ms: Vec<f64>,
    latency_ms: Vec<f64>,
    last_sequence: Option<u64>,
    /// Frames whose times were sampled (valid ones).
    timed_frames: u64,
    recorder: Option<Recorder>,
}

impl<F: WireFrame> LiveTracker<F> {
    /// Loads the models, allocates the tracker and opens the ports. The calling thread
    /// becomes one of the tracker's worker threads: call [`LiveTracker::run`] on it. It
    /// stays one for good (rayon 1.13 cannot release a thread from a pool it joined), so a
    /// thread can start one `LiveTracker`; another start on it is an error.
    pub fn start(config: &TrackerConfig) -> Result<Self> {
        // The models load on a pool of their own, whose threads end with it (rayon's
        // global pool would keep two idle threads for good), and before this thread joins
        // the tracker's pool: a start whose models fail to load leaves the thread free.
        let loading = super::dataset::thread_pool(config.threads)?;
        let loaded = load_tracker(config, &loading, F::WIDTH as usize, F::HEIGHT as usize)?;
        for warning in &loaded.start_pose_warnings {
            log_line(format_args!("tracker: warning: {warning} (`mrsmap track --check` says more)"));
        }
        let tracker = loaded.tracker;
        drop(loading); // its threads end here
        // The calling thread joins the pool as worker 0, so that the parallel work it
        // starts each frame is not injected from outside (rayon allocates for that).
        // `run` must be called on this thread.
        let (pool, placement) = super::dataset::thread_pool_on_this_thread(config.threads, config.pin_threads)?;
        let node = ipc::node("mrsmap_tracker")?;
        let frames_name = config.frame_size.service(&config.camera_service);
        let frames = ipc::frames::<F>(&node, &frames_name)?;
        let frame_events = ipc::events(&node, &frames_name)?;
        let names = tracker.names().to_vec();
        let out = StepOutput::new(tracker.len());
        let initial: Vec<ObjectPose> =
            (0..tracker.len()).map(|k| pose_message(&names[k], &out, k, (0, 0), 0.0)).collect();
        let poses = publish_poses(&node, &config.poses_service, &initial)?;
        let pose_events = ipc::events(&node, &config.poses_service)?;
        let err = |what: &str, name: &str, e: &dyn std::fmt::Debug| IpcError::new(format!("{what} on {name}"), e);
        let subscriber = frames.subscriber_builder().create().map_err(|e| err("subscriber", &frames_name, &e))?;
        let listener = frame_events.listener_builder().create().map_err(|e| err("listener", &frames_name, &e))?;
        let notifier =
            pose_events.notifier_builder().create().map_err(|e| err("pose notifier", &config.poses_service, &e))?;
        let detections =
            DetectionInbox::open(&node, &config.detections_service, config.detection_max_age_ns, tracker.len())?;
        let core = Core {
            out,
            tracker,
            pool,
            names,
            subscriber,
            poses,
            notifier,
            detections,
            track_ms: Vec::with_capacity(RECENT_SAMPLES),
            latency_ms: Vec::with_capacity(RECENT_SAMPLES),
            last_sequence: None,
            timed_frames: 0,
            recorder: None,
        };
        let poses_name = format!("{} (detections from {})", config.poses_service, config.detections_service);
        let other_size_name = config.frame_size.other().service(&config.camera_service);
        Ok(LiveTracker { node, listener, core, frames_name, other_size_name, poses_name, placement })
    }

    /// Says that no frame came, and why when it can tell: a driver publishing the other
    /// image size (`mrsmap camera` with or without `--qvga` against `camera.size`).
    fn report_no_frames(&self) {
        if ipc::frame_service_exists(&self.other_size_name) {
            log_line(format_args!(
                "tracker: no frame on {} for 2 s, but {} exists: is the camera driver publishing the other image \
                 size? (`mrsmap camera --qvga` publishes QVGA; the tracker's size is `camera.size` in its config); waiting",
                self.frames_name, self.other_size_name
            ));
        } else {
            log_line(format_args!(
                "tracker: no frame on {} for 2 s (is a camera driver publishing there?); waiting",
                self.frames_name
            ));
        }
    }

    /// The loop: wait for a frame, track, publish; until a signal or a limit.
    pub fn run(&mut self, limits: &RunLimits, observer: &mut dyn FnMut(&FrameEvent)) -> Result<RunSummary> {
        let mut summary = RunSummary {
            frames: 0,
            invalid_frames: 0,
            skipped_frames: 0,
            stop: StopReason::Signal,
            track_ms: Vec::new(),
            latency_ms: Vec::new(),
            recording_error: None,
            detections: DetectionCounts::default(),
        };
        let mut last_frame = Instant::now();
        let mut waiting_reported = false;
        let objects = self.core.names.iter().map(|n| format!("'{n}'")).collect::<Vec<_>>().join(", ");
        log_line(format_args!(
            "tracker: ready; tracking {objects} on {} thread(s) ({}); frames from {}, poses on {}; waiting for frames",
            self.core.pool.current_num_threads(),
            self.placement,
            self.frames_name,
            self.poses_name
        ));
        loop {
            // Blocks until the driver notifies (or 250 ms pass); no polling.
            // A signal interrupts the wait: that is not an error but the stop request.
            let waited = self.listener.timed_wait(|_| {}, Duration::from_millis(250));
            if self.node.wait(Duration::ZERO).is_err() {
                summary.stop = StopReason::Signal;
                break;
            }
            waited.map_err(|e| IpcError::new("waiting for frames", e))?;
            if self.core.process_newest(&mut summary, observer)? {
                last_frame = Instant::now();
                waiting_reported = false;
                if limits.max_frames.is_some_and(|m| summary.frames >= m) {
                    summary.stop = StopReason::FrameLimit;
                    break;
                }
            } else if last_frame.elapsed() > Duration::from_secs(2) && !waiting_reported {
                self.report_no_frames();
                waiting_reported = true;
            }
            if limits.idle_timeout.is_some_and(|t| last_frame.elapsed() > t) {
                summary.stop = StopReason::Idle;
                break;
            }
        }
        summary.track_ms = self.core.track_ms.clone();
        summary.latency_ms = self.core.latency_ms.clone();
        summary.detections = self.core.detections.counts;
        Ok(summary)
    }

    /// Records the frames and poses of the run into MCAP (see [`Recorder`]).
    pub fn record(&mut self, options: &RecordOptions) -> Result<()> {
        let pixels = (F::WIDTH * F::HEIGHT) as usize;
        let tracker = &self.core.tracker;
        let models: Vec<&SurfelMap> = (0..tracker.len()).map(|k| tracker.model(k)).collect();
        self.core.recorder = Some(Recorder::start(options, &self.core.names, &models, pixels)?);
        log_line(format_args!("tracker: recording to {}", options.path.display()));
        Ok(())
    }

    /// Finishes the recording, if there is one.
    pub fn finish_recording(&mut self) -> Result<Option<RecordStats>> {
        self.core.recorder.take().map(Recorder::finish).transpose()
    }

    /// The node (to list or clean up services).
    pub fn node(&self) -> &Node<Ipc> {
        &self.node
    }
}

impl<F: WireFrame> Core<F> {
    /// Takes the newest frame (older ones are dropped), tracks and publishes. Returns
    /// whether there was a frame.
    fn process_newest(&mut self, summary: &mut RunSummary, observer: &mut dyn FnMut(&FrameEvent)) -> Result<bool> {
        let mut newest = None;
        while let Some(sample) = self.subscriber.receive().map_err(|e| IpcError::new("receiving a frame", e))? {
            if newest.is_some() {
                summary.skipped_frames += 1;
            }
            newest = Some(sample);
        }
        let Some(sample) = newest else { return Ok(false) };
        let received = Instant::now();
        let message = sample.payload();
        let header = *message.header();
        if let Some(last) = self.last_sequence
            && header.sequence > last.saturating_add(1)
        {
            summary.skipped_frames += header.sequence - last - 1;
        }
        self.last_sequence = Some(header.sequence);
        let invalid = match message.frame() {
            Ok(frame) => {
                // Detections that came since the last frame re-initialise their objects
                // first (they wait in the queue through invalid frames).
                self.detections.take(&mut self.tracker, header.capture_stamp_ns)?;
                track_frame(&mut self.tracker, &self.pool, &frame, &mut self.out, Workers::Sleep);
                false
            }
            Err(e) => {
                if summary.invalid_frames == 0 {
                    log_line(format_args!(
                        "tracker: frame {} refused: {e} (reported as invalid; further ones are counted)",
                        header.sequence
                    ));
                }
                invalid_frame(&self.tracker, header.capture_stamp_ns, &mut self.out);
                summary.invalid_frames += 1;
                true
            }
        };
        let total_ms = received.elapsed().as_secs_f32() * 1e3;
        for (k, entry) in self.poses.entries.iter().enumerate() {
            entry.update_with_copy(pose_message(
                &self.names[k],
                &self.out,
                k,
                (header.sequence, header.send_stamp_ns),
                total_ms,
            ));
        }
        self.notifier.notify().map_err(|e| IpcError::new("notifying pose subscribers", e))?;
        // Recorded after the poses are out: the copy does not delay them.
        if let (Some(recorder), Ok(frame)) = (&mut self.recorder, message.frame()) {
            recorder.record(&frame, self.detections.applied(), &self.out);
        }
        drop(sample);
        summary.frames += 1;
        if !invalid {
            let all_objects = self.out.build_ms.iter().zip(&self.out.register_ms).map(|(b, r)| f64::from(b + r)).sum();
            let latency_ms = now_ns().saturating_sub(header.send_stamp_ns) as f64 * 1e-6;
            push_recent(&mut self.track_ms, self.timed_frames, RECENT_SAMPLES, all_objects);
            push_recent(&mut self.latency_ms, self.timed_frames, RECENT_SAMPLES, latency_ms);
            self.timed_frames += 1;
        }
        observer(&FrameEvent { frames: summary.frames, invalid, output: &self.out });
        Ok(true)
    }
}

/// Runs the tracker process described by `config` until SIGINT/SIGTERM or a limit,
/// recording into MCAP if asked.
pub fn run(config: &TrackerConfig, limits: &RunLimits, record: Option<&RecordOptions>) -> Result<RunSummary> {
    match config.frame_size {
        FrameSize::Vga => run_live(LiveTracker::<RgbdFrameVga>::start(config)?, limits, record),
        FrameSize::Qvga => run_live(LiveTracker::<RgbdFrameQvga>::start(config)?, limits, record),
    }
}

fn run_live<F: WireFrame>(
    mut live: LiveTracker<F>,
    limits: &RunLimits,
    record: Option<&RecordOptions>,
) -> Result<RunSummary> {
    if let Some(options) = record {
        live.record(options)?;
    }
    let run = live.run(limits, &mut |_| {});
    // The recording is finished whatever ended the loop (an error too): nothing recorded
    // is lost.
    let recording = live.finish_recording();
    let mut summary = match run {
        Ok(summary) => summary,
        Err(e) => {
            if let Err(r) = &recording {
                log_line(format_args!("tracker: the recording failed too: {r:#}"));
            }
            return Err(e);
        }
    };
    match recording {
        Ok(Some(stats)) => log_line(format_args!(
            "tracker: {} frames recorded ({} left out: the writer was behind)",
            stats.written, stats.dropped
        )),
        Ok(None) => {}
        Err(e) => summary.recording_error = Some(e),
    }
    Ok(summary)
}

/// Prints the summary of a run.
pub fn print_summary(config: &TrackerConfig, s: &RunSummary) {
    let why = match s.stop {
        StopReason::Signal => "stopped by signal",
        StopReason::FrameLimit => "frame limit reached",
        StopReason::Idle => "no frames (idle timeout)",
    };
    println!(
        "tracker: {} frames ({} refused as invalid, {} dropped as stale), {why}",
        s.frames, s.invalid_frames, s.skipped_frames
    );
    if !s.track_ms.is_empty() {
        println!(
            "  tracking {} per frame: median {:.2} ms, p99 {:.2} ms; driver send → poses published: median {:.2} ms, p99 {:.2} ms",
            config.objects.iter().map(|o| format!("'{}'", o.name)).collect::<Vec<_>>().join(" + "),
            percentile(&s.track_ms, 0.5),
            percentile(&s.track_ms, 0.99),
            percentile(&s.latency_ms, 0.5),
            percentile(&s.latency_ms, 0.99)
        );
    }
    let d = &s.detections;
    if d.any() {
        println!(
            "  detections: {} applied, {} not needed (object tracked), {} too old, {} of unknown objects, {} invalid",
            d.applied, d.not_needed, d.stale, d.unknown_object, d.invalid
        );
    }
}
