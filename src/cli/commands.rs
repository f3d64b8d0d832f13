//! What each subcommand does: build the job from the arguments, run it, print.

use super::args::*;
use super::args_live::*;
use anyhow::{Context, Result};
use mrsmap::app;
use mrsmap::app::interrupt::{INTERRUPTED_EXIT, Interrupted, Stop};
use mrsmap::app::outputs::{check_outputs, dataset_and_camera, named, tracker_inputs};
use mrsmap::eval::{Associated, ErrorStats, aligned_positions, associate_stamped, ate_translation, rpe_translation};
use mrsmap::io::tum::Trajectory;
use std::path::Path;
use std::process::ExitCode;

pub fn print_stats(title: &str, s: &ErrorStats) {
    println!("{title} ({} pairs/poses)", s.count);
    println!("  rmse   {:.4} mm", s.rmse * 1e3);
    println!("  mean   {:.4} mm", s.mean * 1e3);
    println!("  median {:.4} mm", s.median * 1e3);
    println!("  std    {:.4} mm", s.std * 1e3);
    println!("  min    {:.4} mm", s.min * 1e3);
    println!("  max    {:.4} mm", s.max * 1e3);
}

/// An optional duration in seconds from the command line.
pub fn seconds(value: Option<f64>, flag: &str) -> Result<Option<std::time::Duration>> {
    value
        .map(|s| {
            std::time::Duration::try_from_secs_f64(s)
                .map_err(|_| anyhow::anyhow!("{flag} must be a number of seconds >= 0"))
        })
        .transpose()
}

/// The exit status of an offline command: 130 if a signal stopped it early (its
/// outputs hold the frames before), 0 otherwise.
fn exit_code(interrupted: Option<Interrupted>) -> ExitCode {
    match interrupted {
        Some(i) => {
            eprintln!("{i}: stopped by a signal; the outputs hold the frames before it");
            ExitCode::from(INTERRUPTED_EXIT)
        }
        None => ExitCode::SUCCESS,
    }
}

/// `mrsmap track`: live, or over a dataset.
pub fn track(a: TrackArgs) -> Result<ExitCode> {
    if a.print_default_config {
        use std::io::Write;
        let text = mrsmap::io::tracker_config::default_tracker_config();
        std::io::stdout().write_all(text.as_bytes()).context("cannot write the configuration to stdout")?;
        return Ok(ExitCode::SUCCESS);
    }
    let config_path = a.config.ok_or_else(|| anyhow::anyhow!("--config is needed (or --print-default-config)"))?;
    let mut config = mrsmap::io::tracker_config::read_tracker_config(&config_path)?;
    if let Some(s) = a.camera_service {
        config.camera_service = s;
    }
    if let Some(s) = a.poses_service {
        config.poses_service = s;
    }
    if let Some(s) = a.detections_service {
        config.detections_service = s;
    }
    if config.detections_service == config.poses_service {
        anyhow::bail!("the detection and pose services are both {}: they must differ", config.poses_service);
    }
    if a.check {
        return check_tracker_config(&config_path, &config);
    }
    if let Some(dataset) = a.dataset {
        let detector =
            simulated_detector(a.reinitialise_at_ground_truth, a.detector_error.as_deref(), a.detector_latency)?;
        let camera = a.camera.ok_or_else(|| anyhow::anyhow!("--dataset needs --camera (the dataset's camera file)"))?;
        let mut inputs = dataset_and_camera(&dataset, Some(&camera));
        inputs.extend(tracker_inputs(&config_path, &config));
        let trajectories = trajectory_files(a.trajectory.as_deref(), &config);
        check_outputs(trajectories.iter().map(|p| ("--trajectory", Some(p.as_path()))), &inputs)?;
        let job = app::track_dataset::TrackDatasetJob {
            dataset,
            camera,
            first_frame: a.first_frame,
            every: a.every as usize,
            max_frames: a.max_frames.map(|m| m as usize),
            qvga: a.qvga,
            start_at_ground_truth: a.start_at_ground_truth || a.reinitialise_at_ground_truth,
            detector,
            trajectory: a.trajectory,
            overlay: a.overlay,
            stop: Stop::on_signals()?,
        };
        let summary = app::track_dataset::run(&config, &job)?;
        app::track_dataset::print_summary(&summary);
        return Ok(exit_code(summary.interrupted));
    }
    let limits = app::tracker_process::RunLimits {
        max_frames: a.max_frames,
        idle_timeout: seconds(a.idle_timeout, "--idle-timeout")?,
    };
    check_outputs([("--record", a.record.as_deref())], &tracker_inputs(&config_path, &config))?;
    let record =
        a.record.map(|path| app::recorder::RecordOptions { path, last_seconds: a.record_last, force: a.force });
    let mut summary = app::tracker_process::run(&config, &limits, record.as_ref())?;
    app::tracker_process::print_summary(&config, &summary);
    // Tracking went on; the failed recording still fails the command, after the summary.
    match summary.recording_error.take() {
        Some(e) => Err(e),
        None => Ok(ExitCode::SUCCESS),
    }
}

/// The exit code of `mrsmap track --check` when the tracker would start but something
/// looks wrong (2 is a command-line error).
const CHECK_WARNINGS_EXIT: u8 = 3;

/// `mrsmap track --check`: exit code 0 when the tracker would start and every object
/// starts in view, [`CHECK_WARNINGS_EXIT`] with warnings; an error (exit code 1) when it
/// would not start.
fn check_tracker_config(path: &Path, config: &mrsmap::io::tracker_config::TrackerConfig) -> Result<ExitCode> {
    let report = app::tracker_check::check(config)?;
    println!("{}: valid", path.display());
    for line in &report.lines {
        println!("{line}");
    }
    for warning in &report.warnings {
        eprintln!("warning: {warning}");
    }
    Ok(if report.warnings.is_empty() { ExitCode::SUCCESS } else { ExitCode::from(CHECK_WARNINGS_EXIT) })
}

/// Default odometry parameters with the map resolution factor λ.
pub fn odometry_params(lambda: f64) -> mrsmap::odometry::OdometryParams {
    let defaults = mrsmap::odometry::OdometryParams::default();
    mrsmap::odometry::OdometryParams { map: mrsmap::map::MapParams { lambda, ..defaults.map }, ..defaults }
}

/// `mrsmap odometry`.
pub fn odometry(a: OdometryArgs) -> Result<ExitCode> {
    check_outputs(
        [("--out", Some(a.out.as_path())), ("--timings", a.timings.as_deref())],
        &dataset_and_camera(&a.dataset, Some(&a.camera)),
    )?;
    let job = app::odometry::OdometryJob {
        dataset: a.dataset,
        camera: a.camera,
        out: a.out,
        timings: a.timings,
        threads: a.threads,
        max_frames: a.max_frames,
        qvga: a.qvga,
        params: odometry_params(a.lambda),
        stop: Stop::on_signals()?,
    };
    let summary = app::odometry::run(&job)?;
    app::odometry::print_summary(&job, &summary);
    Ok(exit_code(summary.interrupted))
}

/// `mrsmap map`.
pub fn map(a: MapArgs) -> Result<ExitCode> {
    let mut params = mrsmap::slam::SlamParams { seed: a.seed, ..Default::default() };
    params.map.lambda = a.lambda;
    let mut inputs = dataset_and_camera(&a.dataset, Some(&a.camera));
    inputs.extend(a.object.as_deref().map(|o| named("the object file", o)));
    check_outputs([("--out", a.out.as_deref()), ("--trajectory", a.trajectory.as_deref())], &inputs)?;
    let job = app::mapper::MapJob {
        dataset: a.dataset,
        camera: a.camera,
        object: a.object,
        out: a.out,
        force: a.force,
        trajectory: a.trajectory,
        threads: a.threads,
        max_frames: a.max_frames,
        params,
        stop: Stop::on_signals()?,
    };
    let summary = app::mapper::run(&job)?;
    app::mapper::print_summary(&job, &summary);
    Ok(exit_code(summary.interrupted))
}

/// `mrsmap model …`.
pub fn model(command: ModelCommand) -> Result<()> {
    match command {
        ModelCommand::Info { file } => print!("{}", app::model_cmd::info(&file)?),
        ModelCommand::Render { file, out, azimuth, elevation, distance, width, height } => {
            if width == 0 || height == 0 || width > 8192 || height > 8192 {
                anyhow::bail!("--width and --height must be 1..=8192 pixels");
            }
            for (flag, value) in [("--azimuth", azimuth), ("--elevation", Some(elevation))] {
                anyhow::ensure!(value.is_none_or(f64::is_finite), "{flag} must be a finite number of degrees");
            }
            if let Some(d) = distance {
                anyhow::ensure!(d.is_finite() && d > 0.0, "--distance must be a finite number of metres > 0, not {d}");
            }
            let view = app::render::View {
                azimuth_deg: azimuth,
                elevation_deg: elevation,
                distance_m: distance,
                width,
                height,
                ..Default::default()
            };
            check_outputs([("--out", Some(out.as_path()))], &[named("the model file", &file)])?;
            let drawn = app::model_cmd::render_file(&file, &out, &view)?;
            println!("{drawn} surfels drawn → {}", out.display());
        }
    }
    Ok(())
}

/// `mrsmap camera`.
pub fn camera(a: CameraArgs) -> Result<()> {
    let input = match (a.dataset, a.mcap, a.camera) {
        (Some(dataset), None, Some(camera)) => app::camera_driver::CameraInput::Dataset { dataset, camera },
        (None, Some(path), camera) => app::camera_driver::CameraInput::Mcap { path, topics: a.topics.topics(), camera },
        _ => anyhow::bail!("give --dataset DIR --camera FILE, or --mcap FILE"),
    };
    let job = app::camera_driver::CameraJob {
        input,
        service: a.service,
        rate_hz: a.rate,
        qvga: a.qvga,
        repeat: match (a.repeat, a.bounce) {
            (_, true) => app::camera_driver::Repeat::Bounce,
            (true, false) => app::camera_driver::Repeat::Loop,
            (false, false) => app::camera_driver::Repeat::Once,
        },
        first_frame: a.first_frame,
        max_frames: a.max_frames,
    };
    let s = app::camera_driver::run(&job)?;
    eprintln!(
        "camera: {} frames sent, {} unreadable{}",
        s.sent,
        s.unreadable,
        if s.signalled { ", stopped by signal" } else { "" }
    );
    if s.sent == 0 && s.unreadable > 0 {
        anyhow::bail!("no frame could be read ({} tried; the reasons are above)", s.unreadable);
    }
    Ok(())
}

/// `mrsmap poses`.
pub fn poses(a: PosesArgs) -> Result<()> {
    use app::poses_client::Printing;
    check_outputs([("--out", a.out.as_deref())], &[])?;
    let job = app::poses_client::PosesJob {
        service: a.service,
        out: a.out,
        force: a.force,
        count: a.count,
        timeout: seconds(a.timeout, "--timeout")?,
        print: match (a.quiet, a.json) {
            (true, _) => Printing::Nothing,
            (false, true) => Printing::Json,
            (false, false) => Printing::Text,
        },
    };
    let s = app::poses_client::run(&job)?;
    // With --json, stdout holds only the poses.
    let summary = app::poses_client::summary_text(&s);
    if a.json {
        eprint!("{summary}")
    } else {
        print!("{summary}")
    }
    Ok(())
}

/// The detector `track --dataset --reinitialise-at-ground-truth` simulates.
fn simulated_detector(
    on: bool,
    error: Option<&[f64]>,
    latency_frames: usize,
) -> Result<Option<app::track_dataset::SimulatedDetector>> {
    if !on {
        return Ok(None);
    }
    let (error_mm, error_deg) = match error {
        Some(&[mm, deg]) => (mm, deg),
        _ => (0.0, 0.0),
    };
    if !(error_mm.is_finite() && error_mm >= 0.0 && error_deg.is_finite() && error_deg >= 0.0) {
        anyhow::bail!("--detector-error takes millimetres and degrees >= 0, not {error_mm} {error_deg}");
    }
    Ok(Some(app::track_dataset::SimulatedDetector {
        latency_frames,
        error_m: error_mm * 1e-3,
        error_rad: error_deg.to_radians(),
    }))
}

/// `mrsmap detect`.
pub fn detect(a: DetectArgs) -> Result<()> {
    use mrsmap::io::wire::ObjectDetection;
    let [tx, ty, tz, qx, qy, qz, qw] = a.pose[..] else { anyhow::bail!("--pose takes 7 numbers") };
    // Checked as the tracker checks the message.
    let message = ObjectDetection {
        translation_m: [tx, ty, tz],
        rotation_xyzw: [qx, qy, qz, qw],
        ..ObjectDetection::new("", &mrsmap::geometry::Pose::identity(), 0, 0)
    };
    let camera_from_object = message.camera_from_object().map_err(|e| anyhow::anyhow!("--pose: {e}"))?;
    let job = app::detect_client::DetectJob {
        service: a.service,
        poses_service: a.poses,
        object: a.object,
        camera_from_object,
        frame_stamp_ns: a.frame_stamp_ns.unwrap_or(0),
        always: a.always,
        timeout: seconds(Some(a.timeout), "--timeout")?.unwrap_or_default(),
    };
    let outcome = app::detect_client::run(&job)?;
    app::detect_client::report(&job, &outcome)
}

/// `mrsmap eval …`.
pub fn eval(command: EvalCommand) -> Result<()> {
    match command {
        EvalCommand::TrackingQuality(a) => {
            for (flag, value) in [
                ("--max-shift", a.max_shift),
                ("--max-turn", a.max_turn),
                ("--fail-mm", a.fail_mm),
                ("--fail-deg", a.fail_deg),
            ] {
                if !(value.is_finite() && value >= 0.0) {
                    anyhow::bail!("{flag} must be a finite number >= 0, not {value}");
                }
            }
            let config = mrsmap::io::tracker_config::read_tracker_config(&a.config)?;
            let mut inputs = app::outputs::tracker_inputs(&a.config, &config);
            inputs.extend(app::outputs::dataset_and_camera(&a.dataset, Some(&a.camera)));
            app::outputs::check_outputs([("--trials-csv", a.trials_csv.as_deref())], &inputs)?;
            let job = app::quality_eval::QualityJob {
                dataset: a.dataset,
                camera: a.camera,
                first_frame: a.first_frame,
                frames: a.frames,
                trials: a.trials,
                max_shift_m: a.max_shift,
                max_turn_rad: a.max_turn.to_radians(),
                fail_mm: a.fail_mm,
                fail_deg: a.fail_deg,
                seed: a.seed,
            };
            let (reference, trials) = app::quality_eval::run(&config, &job)?;
            app::quality_eval::print(
                &job,
                &reference,
                &trials,
                config.params.min_quality,
                config.params.max_free_space,
            );
            if let Some(path) = &a.trials_csv {
                app::report::write_bytes_or_rescue(path, app::quality_eval::trials_csv(&trials).as_bytes())?;
                println!("\nevery registration: {}", path.display());
            }
        }
        EvalCommand::Rpe { gt, est, delta, association, plot } => {
            check_plot(plot.as_deref(), &gt, &est)?;
            let pairs = read_associated(&gt, &est, &association)?;
            let delta = usize::try_from(delta)?;
            let errors = rpe_translation(&pairs.reference, &pairs.estimate, delta)?;
            let title = format!("RPE translation, delta {delta} frame(s)");
            print_stats(&title, &ErrorStats::of(&errors));
            if let Some(path) = plot {
                let stamps: Vec<f64> = pairs.stamps.iter().step_by(delta).copied().take(errors.len()).collect();
                let svg = app::plot::rpe_svg(&plot_title(&title, &est, &gt), &stamps, &errors);
                write_plot(&path, &svg)?;
            }
        }
        EvalCommand::Ate { gt, est, association, plot } => {
            check_plot(plot.as_deref(), &gt, &est)?;
            let pairs = read_associated(&gt, &est, &association)?;
            let errors = ate_translation(&pairs.reference, &pairs.estimate)?;
            let title = "ATE translation after rigid alignment";
            print_stats(title, &ErrorStats::of(&errors));
            if let Some(path) = plot {
                let aligned = aligned_positions(&pairs.reference, &pairs.estimate)?;
                let reference: Vec<_> = pairs.reference.iter().map(|p| p.translation.vector).collect();
                let svg =
                    app::plot::ate_svg(&plot_title(title, &est, &gt), &pairs.stamps, (&reference, &aligned), &errors);
                write_plot(&path, &svg)?;
            }
        }
    }
    Ok(())
}

/// `eval --plot` must not overwrite the trajectories it compares.
fn check_plot(plot: Option<&Path>, gt: &Path, est: &Path) -> Result<()> {
    check_outputs([("--plot", plot)], &[named("the reference trajectory", gt), named("the estimated trajectory", est)])
}

/// The files `--trajectory PATH` becomes: one per object of `config`
/// (`app::poses_client::object_trajectory_path`).
fn trajectory_files(
    path: Option<&Path>,
    config: &mrsmap::io::tracker_config::TrackerConfig,
) -> Vec<std::path::PathBuf> {
    let n = config.objects.len();
    let Some(path) = path else { return Vec::new() };
    config.objects.iter().map(|o| app::poses_client::object_trajectory_path(path, &o.name, n)).collect()
}

fn plot_title(metric: &str, est: &Path, gt: &Path) -> String {
    format!("{metric}\n{} against {}", est.display(), gt.display())
}

pub(super) fn write_plot(path: &Path, svg: &str) -> Result<()> {
    mrsmap::io::atomic::write_whole(path, svg.as_bytes())
        .with_context(|| format!("writing the plot {}", path.display()))?;
    println!("plot: {}", path.display());
    Ok(())
}

/// The reference's and the estimate's poses paired by stamp, the estimate's stamps
/// shifted by `--offset` first.
fn read_associated(gt: &Path, est: &Path, a: &AssociationArgs) -> Result<Associated> {
    anyhow::ensure!(a.offset.is_finite(), "--offset must be a finite number of seconds, not {}", a.offset);
    let reference = Trajectory::read(gt)?;
    let mut estimate = Trajectory::read(est)?;
    warn_if_out_of_order(gt, &reference);
    warn_if_out_of_order(est, &estimate);
    estimate.stamps.iter_mut().for_each(|t| *t += a.offset);
    Ok(associate_stamped(&reference, &estimate, a.max_diff)?)
}

/// Says so when a trajectory's stamps are not strictly increasing (a camera driver that
/// looped its sequence, two runs written into one file): the TUM benchmark's scripts
/// would sort such a file and keep one pose per stamp, evo (and this tool) pair the poses
/// in the file's order, and the two give different numbers.
fn warn_if_out_of_order(path: &Path, trajectory: &Trajectory) {
    let stamps = &trajectory.stamps;
    if let Some(k) = stamps.windows(2).position(|w| w[1] <= w[0]) {
        eprintln!(
            "warning: {}: pose {} (stamp {:.6}) is not after pose {} (stamp {:.6}); the poses are paired in the \
             file's order, as evo does (the TUM benchmark's scripts would sort them and keep one pose per stamp)",
            path.display(),
            k + 2,
            stamps[k + 1],
            k + 1,
            stamps[k]
        );
    }
}

/// `mrsmap demo`.
pub fn demo(a: DemoArgs) -> Result<()> {
    app::demo::run(&app::demo::DemoJob { config: a.config, dataset: a.dataset, camera: a.camera, rate_hz: a.rate })
}

/// `mrsmap replay`.
pub fn replay(a: ReplayArgs) -> Result<ExitCode> {
    let mut config = mrsmap::io::tracker_config::read_tracker_config(&a.config)?;
    config.threads = a.threads.or(config.threads);
    let camera = a.camera.as_deref().map(mrsmap::io::camera_file::read_camera).transpose()?;
    let mut inputs = vec![named("the input recording", &a.input)];
    inputs.extend(tracker_inputs(&a.config, &config));
    inputs.extend(a.camera.as_deref().map(|c| named("the camera file", c)));
    inputs.extend(a.groundtruth.as_deref().map(|g| named("the ground truth", g)));
    let trajectories = trajectory_files(a.trajectory.as_deref(), &config);
    let outputs = std::iter::once(("--out", a.out.as_deref()))
        .chain(trajectories.iter().map(|p| ("--trajectory", Some(p.as_path()))));
    check_outputs(outputs, &inputs)?;
    let job = app::replay::ReplayJob {
        input: a.input,
        out: a.out,
        force: a.force,
        trajectory: a.trajectory,
        topics: a.topics.topics(),
        camera,
        groundtruth: a.groundtruth,
        every: a.every,
        qvga: a.qvga,
        max_frames: a.max_frames,
        stop: Stop::on_signals()?,
    };
    let summary = app::replay::run(&config, &job)?;
    app::replay::print_summary(&summary);
    if let Some(out) = &job.out {
        println!("poses written to {}", out.display());
    }
    Ok(exit_code(summary.interrupted))
}

/// `mrsmap convert`.
pub fn convert(c: ConvertCommand) -> Result<ExitCode> {
    match c {
        ConvertCommand::TumToMcap(a) => {
            check_outputs([("--out", Some(a.out.as_path()))], &dataset_and_camera(&a.dataset, a.camera.as_deref()))?;
            let job = app::convert::ConvertJob {
                dataset: a.dataset,
                camera: a.camera,
                out: a.out,
                force: a.force,
                depth_encoding: if a.depth_encoding == "32FC1" {
                    mrsmap::io::mcap_write::DepthEncoding::M32
                } else {
                    mrsmap::io::mcap_write::DepthEncoding::Mm16
                },
                compression: if a.compression == "lz4" { mcap::Compression::Lz4 } else { mcap::Compression::Zstd },
                chunk_bytes: a.chunk_size,
                topics: a.topics.topics(),
                first_frame: a.first_frame,
                max_frames: a.max_frames,
                stop: Stop::on_signals()?,
            };
            let s = app::convert::run(&job)?;
            println!("{} frames written to {} ({} unreadable frames skipped)", s.written, job.out.display(), s.skipped);
            Ok(exit_code(s.interrupted))
        }
    }
}

/// `mrsmap synth`.
pub fn synth(a: SynthArgs) -> Result<ExitCode> {
    let job = app::synth::SynthJob {
        scene: a.scene,
        out: a.out,
        sequences: a.sequences,
        force: a.force,
        max_frames: a.max_frames,
        stop: Stop::on_signals()?,
    };
    let summary = app::synth::run(&job)?;
    for s in &summary.sequences {
        println!("{}: {} frames in {}", s.name, s.frames, s.folder.display());
    }
    Ok(exit_code(summary.interrupted))
}
