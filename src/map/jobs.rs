//! How a parallel loop is cut into rayon jobs.
//!
//! Every parallel loop of map building and registration runs over fixed work items
//! (bands of rows, chunks of nodes or surfels), each writing its own output, so the
//! result is the same however the items are shared between threads. Only the time
//! depends on the sharing. rayon cuts an indexed loop over two threads into about four
//! parts of equal item counts, not of equal costs: the bands of rows around an object
//! cost far more than those above it, and so do the chunks of surfels on it. The
//! thread that finishes its parts first then waits for the other. With one job per item
//! it takes over the rest item by item. On the 2-core machine of `docs/benchmarks-history.md`
//! (stop 46) this made the tracker's step 3–5 % faster at VGA and QVGA, and odometry
//! up to 8 % at QVGA (frames paired within one run); the extra joins cost 0.4 % of the
//! instructions.
//!
//! Also measured there: running the loops of few items (a coarse level's association
//! or merge) on the calling thread alone, to spare waking the second worker, was slower
//! than sharing them too.

use rayon::iter::{IndexedParallelIterator, MaxLen};

/// Cuts a parallel loop into one job per item.
pub(crate) trait ItemJobs: IndexedParallelIterator {
    /// This loop with one rayon job per item.
    fn item_jobs(self) -> MaxLen<Self> {
        self.with_max_len(1)
    }
}

impl<I: IndexedParallelIterator> ItemJobs for I {}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    #[test]
    fn a_loop_with_one_job_per_item_shares_its_items_between_the_workers() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("a pool");
        let mut ran_on = [usize::MAX; 8];
        pool.install(|| {
            // The first item is long: rayon's own cut (two halves, then quarters) would
            // leave the second and, at best, third quarter to one worker; item by item,
            // the other worker takes all the rest.
            ran_on.par_iter_mut().enumerate().item_jobs().for_each(|(i, t)| {
                let ms = if i == 0 { 200 } else { 5 };
                std::thread::sleep(std::time::Duration::from_millis(ms));
                *t = rayon::current_thread_index().unwrap_or(usize::MAX);
            });
        });
        let first = ran_on[0];
        assert!(ran_on[1..].iter().all(|&t| t < 2 && t != first), "{ran_on:?}");
    }
}
