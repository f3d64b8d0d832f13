//! What the dataset jobs share: the starting pose, the thread pool, the frame list.

use super::affinity::{self, Placement};
use crate::geometry::Pose;
use crate::io::tum::{TumDataset, format_stamp};
use anyhow::{Context, Result};
use std::fmt::Write as _;

/// The pose of the first frame: ground truth interpolated at its depth stamp if the
/// dataset has it (the nearest sample if the frame is just outside the span), identity
/// otherwise. What was done is appended to `notes`.
pub fn initial_pose(dataset: &TumDataset, stamp_ns: u64, notes: &mut String) -> Pose {
    let Some(gt) = &dataset.groundtruth else {
        let _ = writeln!(notes, "no groundtruth.txt: trajectory starts at identity");
        return Pose::identity();
    };
    let stamp = stamp_ns as f64 * 1e-9;
    if let Some(p) = gt.interpolate(stamp, 0.1) {
        let _ = writeln!(notes, "starts at the ground-truth pose interpolated at {}", format_stamp(stamp_ns));
        return p;
    }
    match gt.nearest(stamp) {
        Some((p, dt)) if dt < 1.0 => {
            let _ = writeln!(
                notes,
                "first frame is {dt:.3} s outside the ground truth: starts at the nearest ground-truth pose"
            );
            p
        }
        _ => {
            let _ = writeln!(notes, "first frame is far from any ground-truth pose: trajectory starts at identity");
            Pose::identity()
        }
    }
}

/// Runs `work` inside `pool`, one more worker spinning until it is done: taking the
/// jobs `work` shares out as soon as they appear, instead of falling asleep between
/// them and being woken for the next (tens of microseconds each on a virtual machine).
/// For frames processed back to back with nothing else running (offline tracking,
/// odometry and mapping over a dataset): there it made the step 2–5 % faster (`docs/benchmarks-history.md`,
/// "Two cores, one job per piece"). Not for the live tracker: after the camera's idle
/// gap between frames a spinning worker slowed the step by half instead (the host seems
/// to give both virtual cores one physical core then). The replay runs it beside the
/// read of its next frame (`app::read_ahead`): the worker that reads joins the step
/// when it is done. The results do not depend on it.
pub fn install_spinning<R: Send>(pool: &rayon::ThreadPool, work: impl FnOnce() -> R + Send) -> R {
    use std::sync::atomic::{AtomicBool, Ordering};
    /// Sets the flag when dropped: also when `work` panics, or the spinner would wait
    /// for ever (and `join` with it).
    struct SetOnDrop<'a>(&'a AtomicBool);
    impl Drop for SetOnDrop<'_> {
        fn drop(&mut self) {
            self.0.store(true, Ordering::Release);
        }
    }
    pool.install(|| {
        let done = AtomicBool::new(false);
        let (result, ()) = rayon::join(
            || {
                let _done = SetOnDrop(&done);
                work()
            },
            || {
                // Stolen by another worker, this waits for `work`'s jobs (run on the
                // calling thread once `work` is done, it returns at once).
                while !done.load(Ordering::Acquire) {
                    if rayon::yield_now() != Some(rayon::Yield::Executed) {
                        std::hint::spin_loop();
                    }
                }
            },
        );
        result
    })
}

/// A rayon pool with `threads` workers (all cores by default).
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    build_pool(rayon::ThreadPoolBuilder::new(), threads)
}

/// [`thread_pool`] whose worker 0 is the calling thread: parallel work started on it
/// begins there instead of being injected from outside (rayon allocates for that, and a
/// pool thread woken after an idle gap may start late). The thread stays in the pool for
/// good (rayon 1.13 cannot release it), so it can join one such pool only. With `pin`,
/// each worker is restricted to a CPU of its own ([`super::affinity`]); the placement
/// says what was done.
pub fn thread_pool_on_this_thread(threads: Option<usize>, pin: bool) -> Result<(rayon::ThreadPool, Placement)> {
    let pool = build_pool(rayon::ThreadPoolBuilder::new().use_current_thread(), threads)?;
    let placement = if pin { pin_workers(&pool) } else { Placement::Free("pin_threads = false".into()) };
    Ok((pool, placement))
}

/// Pins worker `i` of `pool` to the `i`-th CPU the process may use; if any worker
/// cannot be pinned, every worker gets the whole mask back (the planned CPUs are all the
/// process may use).
fn pin_workers(pool: &rayon::ThreadPool) -> Placement {
    let plan = affinity::plan(pool.current_num_threads(), affinity::allowed_cpus());
    let failures: Vec<String> =
        pool.broadcast(|ctx| plan.pin_worker(ctx.index()).err().map(|e| e.to_string())).into_iter().flatten().collect();
    match (failures.first(), &plan) {
        (Some(why), Placement::Pinned { cpus }) => {
            pool.broadcast(|_| affinity::allow_current_thread(cpus));
            Placement::Free(format!("pinning failed ({why})"))
        }
        _ => plan,
    }
}

fn build_pool(mut pool: rayon::ThreadPoolBuilder, threads: Option<usize>) -> Result<rayon::ThreadPool> {
    if let Some(t) = threads {
        pool = pool.num_threads(t);
    }
    pool.build().context("starting the thread pool")
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    #[test]
    fn a_spinning_install_gives_the_work_s_result_and_ends_when_the_work_panics() {
        let pool = thread_pool(Some(2)).expect("a pool");
        for _ in 0..50 {
            let sum = install_spinning(&pool, || {
                (0..10_000u32).into_par_iter().with_max_len(100).map(u64::from).sum::<u64>()
            });
            assert_eq!(sum, 49_995_000);
        }
        // The spinner stops also when the work panics (else this would never return).
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            install_spinning(&pool, || -> u64 { panic!("a failing step") })
        }));
        assert!(outcome.is_err());
        assert_eq!(install_spinning(&pool, || 7), 7, "the pool still works");
    }
}
