//! What the dataset jobs share: the starting pose, the thread pool, the frame list.

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

/// A rayon pool with `threads` workers (all cores by default).
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    build_pool(rayon::ThreadPoolBuilder::new(), threads)
}

/// [`thread_pool`] whose worker 0 is the calling thread: parallel work started on it
/// begins there instead of being injected from outside (rayon allocates for that, and a
/// pool thread woken after an idle gap may start late). The thread stays in the pool for
/// good (rayon 1.13 cannot release it), so it can join one such pool only.
pub fn thread_pool_on_this_thread(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    build_pool(rayon::ThreadPoolBuilder::new().use_current_thread(), threads)
}

fn build_pool(mut pool: rayon::ThreadPoolBuilder, threads: Option<usize>) -> Result<rayon::ThreadPool> {
    if let Some(t) = threads {
        pool = pool.num_threads(t);
    }
    pool.build().context("starting the thread pool")
}
