//! How long after a serial stretch does the second worker of a rayon pool start on
//! parallel work? (docs/benchmarks-history.md, stop 31.)
//!
//! Within a frame, map building alternates parallel regions with serial ones (the sort
//! of the aggregates and the creation of the tree: ~0.4 ms per VGA frame). A rayon
//! worker that finds no work spins briefly, then sleeps; the next region then runs on
//! one core until the sleeper is awake. Per length of the serial stretch this prints
//! how long the other worker took to pick up the second half of a `rayon::join`
//! (median, 90th percentile and maximum over 200 trials; 3000 µs = not within 3 ms).
//!
//! ```sh
//! cargo run --release --example steal_latency
//! ```

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Busy work for `d` on the calling thread.
fn spin(d: Duration) {
    let start = Instant::now();
    while start.elapsed() < d {
        std::hint::spin_loop();
    }
}

/// Microseconds until the other worker started the second half of a join (the first
/// half waits for it, up to 3 ms).
fn steal_latency_us() -> f64 {
    let started = AtomicBool::new(false);
    let t0 = Instant::now();
    let limit = Duration::from_millis(3);
    let (taken, ()) = rayon::join(
        || {
            while !started.load(Ordering::Acquire) && t0.elapsed() < limit {
                std::hint::spin_loop();
            }
            started.load(Ordering::Acquire).then(|| t0.elapsed())
        },
        || started.store(true, Ordering::Release),
    );
    taken.map_or(3000.0, |d| d.as_secs_f64() * 1e6)
}

fn main() {
    let pool = match rayon::ThreadPoolBuilder::new().num_threads(2).build() {
        Ok(pool) => pool,
        Err(e) => {
            eprintln!("cannot start a pool of two threads: {e}");
            std::process::exit(1);
        }
    };
    println!("| serial stretch before the region (µs) | other worker starts after: median / p90 / max (µs) |");
    println!("|---|---|");
    pool.install(|| {
        for serial_us in [0u64, 20, 50, 100, 200, 500, 2000] {
            let mut latency: Vec<f64> = (0..200)
                .map(|_| {
                    spin(Duration::from_micros(serial_us));
                    steal_latency_us()
                })
                .collect();
            latency.sort_by(f64::total_cmp);
            println!("| {serial_us} | {:.1} / {:.1} / {:.1} |", latency[100], latency[180], latency[199]);
        }
    });
}
