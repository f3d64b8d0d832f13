//! Does a second core join parallel work after the process idled? (docs/benchmarks-history.md,
//! "The live tracker after an idle gap".)
//!
//! A rayon pool of two runs "frames" shaped like a tracker step: 20 parallel regions,
//! each two halves of 300 µs (`rayon::join`), with 200 µs of serial work between them.
//! Before each frame the process sleeps for a gap, as a live tracker idles between
//! camera frames. Per gap it prints the median frame time and how many regions the
//! second worker took: 10 ms and 100 % when it joins every region, 16 ms and 0 % when
//! one core does all the work.
//!
//! ```sh
//! cargo run --release --example worker_wake [FRAMES_PER_GAP] [GAP_MS...]
//! ```

use std::time::{Duration, Instant};

const REGIONS: usize = 20;
const HALF: Duration = Duration::from_micros(300);
const SERIAL: Duration = Duration::from_micros(200);

/// Busy work for `d` (the same wall time whatever the core's speed).
fn spin(d: Duration) {
    let start = Instant::now();
    while start.elapsed() < d {
        std::hint::spin_loop();
    }
}

/// One frame on the pool's worker 0: its time and the regions whose second half ran on
/// the other worker.
fn frame(pool: &rayon::ThreadPool) -> (Duration, usize) {
    pool.install(|| {
        let start = Instant::now();
        let mut taken = 0;
        for _ in 0..REGIONS {
            let me = rayon::current_thread_index();
            let (_, other) = rayon::join(
                || spin(HALF),
                || {
                    spin(HALF);
                    rayon::current_thread_index()
                },
            );
            taken += usize::from(other != me);
            spin(SERIAL);
        }
        (start.elapsed(), taken)
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let frames: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(20);
    let mut gaps_ms: Vec<u64> = args.map(|a| a.parse()).collect::<Result<_, _>>()?;
    if gaps_ms.is_empty() {
        gaps_ms = vec![0, 5, 10, 20, 33];
    }
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build()?;
    println!("{REGIONS} regions of 2 × {HALF:?} with {SERIAL:?} serial between them; {frames} frames per gap");
    println!(
        "| idle gap before each frame (ms) | frame median (ms) | frame max (ms) | regions the second worker took |"
    );
    println!("|---|---|---|---|");
    for gap in gaps_ms {
        let mut times = Vec::with_capacity(frames);
        let mut taken = 0;
        for _ in 0..frames {
            std::thread::sleep(Duration::from_millis(gap));
            let (t, k) = frame(&pool);
            times.push(t.as_secs_f64() * 1e3);
            taken += k;
        }
        times.sort_by(f64::total_cmp);
        let median = times.get(times.len() / 2).copied().unwrap_or(f64::NAN);
        let max = times.last().copied().unwrap_or(f64::NAN);
        let share = 100.0 * taken as f64 / (frames * REGIONS).max(1) as f64;
        println!("| {gap} | {median:.2} | {max:.2} | {share:.0} % |");
    }
    println!("(ideal with two cores: 10 ms; one core alone: 16 ms)");
    Ok(())
}
