//! How many cores the machine really gives right now, for reading benchmark figures.
//!
//! On a shared robot computer or a virtual machine, "2 threads" does not always mean two
//! free cores: other processes or the hypervisor may hold one. A fixed arithmetic kernel
//! (four independent integer chains, no memory traffic) is timed on one thread, then on
//! `threads` threads at once, each doing the same work. If every thread got its own
//! core, both take the same time and the capacity is `threads`; with one core shared by
//! two threads it is about 1. The one-thread time itself says how fast a core is now:
//! on a virtual machine the same core can run at half speed while its host is busy.

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

/// The time `threads` threads take to run the kernel together: from a common start to
/// the last one's end. With as many threads as the process has CPUs, each runs on a CPU
/// of its own (`super::affinity`, as the live tracker's workers): unpinned, a thread
/// started after a few seconds of two-core work was placed on the busy CPU and stayed
/// there for the whole run (the capacity read ×1.0 with the other CPU idle, on the Intel
/// VM of stop 54; starting the threads from a sleep helped only in some runs).
fn timed(threads: usize) -> Duration {
    use std::sync::Barrier;
    let n = black_box(KERNEL_ITERATIONS);
    let start = Barrier::new(threads);
    let placement = (threads > 1).then(|| super::affinity::plan(threads, super::affinity::allowed_cpus()));
    let run = |index: usize| {
        if let Some(p) = &placement {
            // Best effort: unpinned, the figure can only read low.
            let _ = p.pin_worker(index);
        }
        start.wait();
        let t = Instant::now();
        black_box(kernel(n));
        (t, Instant::now())
    };
    let spans: Vec<(Instant, Instant)> = std::thread::scope(|s| {
        let run = &run;
        let all: Vec<_> = (0..threads).map(|i| s.spawn(move || run(i))).collect();
        all.into_iter().filter_map(|h| h.join().ok()).collect()
    });
    let first = spans.iter().map(|s| s.0).min();
    let last = spans.iter().map(|s| s.1).max();
    match (first, last) {
        (Some(first), Some(last)) => last - first,
        _ => Duration::ZERO,
    }
}

/// What the cores gave during a probe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capacity {
    /// `threads · t₁ / tₙ`: how many cores the threads really had (1 for one thread).
    pub parallel: f64,
    /// The kernel's time on one thread (ms, median): the speed of one core now. On a
    /// shared host the same core may be twice as slow in a busy hour; compare it with
    /// the figure of a quiet moment on the same machine (docs/benchmarks.md).
    pub one_thread_ms: f64,
}

/// The capacity available to `threads` threads now: the median of three rounds of one
/// thread, then all threads (about 0.1 s in all for two threads).
pub fn probe(threads: usize) -> Capacity {
    let threads = threads.max(1);
    let mut ones = Vec::with_capacity(ROUNDS);
    let mut ratios = Vec::with_capacity(ROUNDS);
    for _ in 0..ROUNDS {
        let one = timed(1).as_secs_f64();
        ones.push(one * 1e3);
        if threads > 1 {
            let all = timed(threads).as_secs_f64();
            ratios.push(threads as f64 * one / all.max(f64::MIN_POSITIVE));
        }
    }
    let parallel = if threads == 1 { 1.0 } else { super::report::percentile(&ratios, 0.5) };
    Capacity { parallel, one_thread_ms: super::report::percentile(&ones, 0.5) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_thread_has_one_core_and_takes_time() {
        let c = probe(1);
        assert_eq!(c.parallel, 1.0);
        assert!(c.one_thread_ms > 0.0 && c.one_thread_ms.is_finite(), "{c:?}");
    }
}
