//! How many cores the machine really gives right now, for reading benchmark figures.
//!
//! On a shared robot computer or a virtual machine, "2 threads" does not always mean two
//! free cores: other processes or the hypervisor may hold one. A fixed arithmetic kernel
//! (four independent integer chains, no memory traffic) is timed on one thread, then on
//! `threads` threads at once, each doing the same work. If every thread got its own
//! core, both take the same time and the capacity is `threads`; with one core shared by
//! two threads it is about 1.

use std::hint::black_box;
use std::time::{Duration, Instant};

/// Iterations of the kernel: about 10 ms on one core of a current x86-64.
const KERNEL_ITERATIONS: u64 = 12_000_000;

/// Rounds of (one thread, all threads); the median ratio is reported.
const ROUNDS: usize = 3;

/// Four independent dependency chains of cheap integer operations.
#[inline(never)]
fn kernel(n: u64) -> u64 {
    let (mut a, mut b, mut c, mut d) = (1u64, 2u64, 3u64, 4u64);
    for i in 0..n {
        a = a.wrapping_add(i ^ b);
        b = b.wrapping_add(i ^ c);
        c = c.wrapping_add(i ^ d);
        d = d.wrapping_add(i ^ a);
    }
    a ^ b ^ c ^ d
}

fn timed(threads: usize) -> Duration {
    let n = black_box(KERNEL_ITERATIONS);
    let t = Instant::now();
    std::thread::scope(|s| {
        let others: Vec<_> = (1..threads).map(|_| s.spawn(move || black_box(kernel(n)))).collect();
        black_box(kernel(n));
        for h in others {
            let _ = h.join();
        }
    });
    t.elapsed()
}

/// The parallel capacity available to `threads` threads now: `threads · t₁ / tₙ`, the
/// median of three rounds (about 0.1 s in all for two threads). 1 thread gives 1.
pub fn parallel_capacity(threads: usize) -> f64 {
    let threads = threads.max(1);
    if threads == 1 {
        return 1.0;
    }
    let ratios: Vec<f64> = (0..ROUNDS)
        .map(|_| {
            let one = timed(1).as_secs_f64();
            let all = timed(threads).as_secs_f64();
            threads as f64 * one / all.max(f64::MIN_POSITIVE)
        })
        .collect();
    super::report::percentile(&ratios, 0.5)
}
