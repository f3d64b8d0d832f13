//! `mrsmap bench`: the per-frame times of map building and registration (odometry) and
//! of the tracker's step, as Markdown tables and, with `--plot`, a picture of every
//! frame's time.

use super::args::BenchArgs;
use super::commands::{odometry_params, write_plot};
use anyhow::Result;
use mrsmap::app;
use mrsmap::app::bench::{BenchResult, TrackingTimes};
use mrsmap::app::outputs::{check_outputs, dataset_and_camera, tracker_inputs};
use mrsmap::app::plot::TimeSeries;

/// `mrsmap bench`.
pub fn bench(a: BenchArgs) -> Result<()> {
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
    anyhow::ensure!(
        a.frame_gap_ms.is_finite() && (0.0..=10_000.0).contains(&a.frame_gap_ms),
        "--frame-gap-ms must be between 0 and 10000 ms, not {}",
        a.frame_gap_ms
    );
    // Read before the odometry runs, so that a bad file is said at once.
    let tracking = a.tracking_config.as_deref().map(mrsmap::io::tracker_config::read_tracker_config).transpose()?;
    // And a picture that could not be written, or would replace an input, is said
    // before minutes of runs.
    let mut inputs = dataset_and_camera(&job.dataset, Some(&job.camera));
    if let (Some(path), Some(config)) = (&a.tracking_config, &tracking) {
        inputs.extend(tracker_inputs(path, config));
    }
    check_outputs([("--plot", a.plot.as_deref())], &inputs)?;
    let threads = a.threads.unwrap_or_else(rayon::current_num_threads);
    let before = app::capacity::probe(threads);
    let cpu = app::bench::cpu_model().unwrap_or_else(|| "unknown".into());
    let cpus = std::thread::available_parallelism().map_or_else(|_| "?".into(), |n| n.to_string());
    println!("machine: {cpu}, {cpus} logical CPUs");
    println!("compiled for: {}\n", app::bench::instruction_set());
    let results = app::bench::run(&job)?;
    app::bench::print(&results, threads);
    let mut series: Vec<TimeSeries> = results.iter().map(odometry_series).collect();
    if let Some(config) = &tracking {
        let gap = std::time::Duration::from_secs_f64(a.frame_gap_ms * 1e-3);
        let gap_note =
            if gap.is_zero() { String::new() } else { format!(", {} ms idle before each frame", a.frame_gap_ms) };
        println!(
            "\n| tracking{gap_note} | object | threads | frames (estimated) | per frame median / p99 (ms) | scene map / registration median (ms) | first frame (ms) |"
        );
        println!("|---|---|---|---|---|---|---|");
        for &res in &job.resolutions {
            let half = res == app::bench::Resolution::Qvga;
            let size = if half { "QVGA 320×240" } else { "VGA 640×480" };
            let t = app::bench::tracking_ms(config, &job, a.tracking_first_frame, half, gap)?;
            app::bench::print_tracking(&t, size, threads);
            series.extend(tracking_series(&t, size));
        }
    }
    // No times without key views (`--graph-key-views 0`): nothing to print.
    let (edges, ms) = app::bench::graph_step_ms(job.graph_key_views, 50);
    if !ms.is_empty() {
        println!(
            "\npose-graph step (synthetic, {} key views, {edges} edges, 50 on-line steps): median {:.2} ms, p99 {:.2} ms",
            job.graph_key_views,
            app::report::percentile(&ms, 0.5),
            app::report::percentile(&ms, 0.99)
        );
    }
    let after = app::capacity::probe(threads);
    println!(
        "\nCPU now (a fixed arithmetic loop): one thread ran it in {:.1} ms before and {:.1} ms after the runs \
         (docs/benchmarks.md has this machine's figure at a quiet moment; a larger one means a slowed \
         core, and the figures above are slower in proportion)",
        before.one_thread_ms, after.one_thread_ms
    );
    if threads > 1 {
        println!(
            "CPU capacity for {threads} threads (the loop on all threads against one): ×{:.2} before, ×{:.2} after \
             ({threads} = every thread had a free core; less means other load took cores)",
            before.parallel, after.parallel
        );
    }
    if let Some(path) = &a.plot {
        let title = format!(
            "mrsmap bench: {cpu}, {threads} threads, {} passes\nprobe loop {:.1} ms before, {:.1} ms after the runs \
             (a slowed core reads above its quiet figure); capacity ×{:.2} / ×{:.2}",
            job.passes, before.one_thread_ms, after.one_thread_ms, before.parallel, after.parallel
        );
        write_plot(path, &app::plot::times_svg(&title, &series))?;
    }
    Ok(())
}

/// The odometry frames of one resolution as they ran.
fn odometry_series(r: &BenchResult) -> TimeSeries {
    TimeSeries {
        name: format!("odometry {} {}×{}: map building + registration", r.label, r.width, r.height),
        ms: r.total_ms.clone(),
        pass_starts: r.pass_starts.clone(),
    }
}

/// The tracked frames of each object at one size, as they ran.
fn tracking_series(t: &TrackingTimes, size: &str) -> Vec<TimeSeries> {
    t.objects
        .iter()
        .map(|o| TimeSeries {
            name: format!("tracking {size}, {}: the step for the object", o.name),
            ms: o.steady_ms.clone(),
            pass_starts: t.pass_starts.clone(),
        })
        .collect()
}
