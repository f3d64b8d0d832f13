//! One CPU per worker thread, for the live tracker.
//!
//! Between camera frames the tracker idles for tens of milliseconds. When the next frame
//! wakes its second worker, Linux may place that worker on the CPU that is already busy
//! with the first one (on a virtual machine it does so when the idle virtual CPU has been
//! descheduled by its host; `available_idle_cpu` then reads it as taken), and there the
//! two share one core until the load balancer moves one of them, which takes longer than
//! a frame. Measured on the Intel VM (`examples/worker_wake.rs`, docs/benchmarks-history.md, stop
//! 54): after a 33 ms idle gap the second worker took 10 % of the parallel regions
//! unpinned and 100 % pinned. A worker pinned to a CPU of its own cannot be placed
//! anywhere else: its wake-up waits for its own CPU instead.
//!
//! Workers are pinned when there are exactly as many as CPUs the process may use: worker
//! `i` to the `i`-th of them, in ascending order. That is the default (as many workers as
//! cores), or the user chose the CPUs: `taskset -c 2,3 mrsmap track ...` (or a cpuset
//! cgroup) with two threads. With more usable CPUs than workers, which ones to take is
//! the user's choice, not ours (two tracker processes would both take the first ones);
//! with fewer, one CPU each is impossible. In both cases nothing is pinned, and the
//! placement says why.

use rustix::thread::{CpuSet, sched_getaffinity, sched_setaffinity};

/// Where a pool's workers run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Placement {
    /// Worker `i` runs only on `cpus[i]`.
    Pinned {
        /// The CPU of each worker, by worker index.
        cpus: Vec<usize>,
    },
    /// The scheduler places the workers; why they were not pinned.
    Free(String),
}

impl Placement {
    /// The CPU worker `index` is to be pinned to, if any.
    pub fn cpu_of(&self, index: usize) -> Option<usize> {
        match self {
            Placement::Pinned { cpus } => cpus.get(index).copied(),
            Placement::Free(_) => None,
        }
    }

    /// Restricts the calling thread, worker `index`, to its planned CPU (nothing if it
    /// has none); an error names the CPU.
    pub fn pin_worker(&self, index: usize) -> std::io::Result<()> {
        match self.cpu_of(index) {
            Some(cpu) => pin_current_thread(cpu).map_err(|e| std::io::Error::new(e.kind(), format!("CPU {cpu}: {e}"))),
            None => Ok(()),
        }
    }
}

impl std::fmt::Display for Placement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Placement::Pinned { cpus } => {
                let list: Vec<String> = cpus.iter().map(|c| c.to_string()).collect();
                let s = if cpus.len() == 1 { "" } else { "s" };
                write!(f, "workers pinned to CPU{s} {}", list.join(", "))
            }
            Placement::Free(why) => write!(f, "workers not pinned: {why}"),
        }
    }
}

/// The CPUs this process may run on (its affinity mask: `taskset`, cpuset cgroups), in
/// ascending order.
pub fn allowed_cpus() -> std::io::Result<Vec<usize>> {
    let set = sched_getaffinity(None)?;
    Ok((0..CpuSet::MAX_CPU).filter(|&c| set.is_set(c)).collect())
}

/// The plan for `threads` workers: one allowed CPU each when there are as many allowed
/// CPUs as workers, or why not.
pub fn plan(threads: usize, allowed: std::io::Result<Vec<usize>>) -> Placement {
    let cpus = match allowed {
        Err(e) => return Placement::Free(format!("cannot read the process's CPU affinity ({e})")),
        Ok(cpus) => cpus,
    };
    let plural = |n: usize| if n == 1 { "" } else { "s" };
    let (n, t) = (cpus.len(), threads);
    if n < t {
        Placement::Free(format!("{t} worker thread{} but only {n} usable CPU{}", plural(t), plural(n)))
    } else if n > t {
        Placement::Free(format!(
            "{t} worker thread{} may run on {n} CPUs; to pin {}, start the tracker on {t} CPU{} \
             (e.g. `taskset -c {}`)",
            plural(t),
            if t == 1 { "it" } else { "them" },
            plural(t),
            cpus[n - t..].iter().map(|c| c.to_string()).collect::<Vec<_>>().join(",")
        ))
    } else {
        Placement::Pinned { cpus }
    }
}

/// Restricts the calling thread to `cpu`.
pub fn pin_current_thread(cpu: usize) -> std::io::Result<()> {
    restrict_current_thread(&[cpu])
}

/// Lets the calling thread run on any of `cpus` again (an empty list changes nothing).
pub fn allow_current_thread(cpus: &[usize]) {
    if !cpus.is_empty() {
        // Best effort: the mask was the thread's own a moment ago.
        let _ = restrict_current_thread(cpus);
    }
}

/// Sets the calling thread's affinity mask to `cpus`.
fn restrict_current_thread(cpus: &[usize]) -> std::io::Result<()> {
    let mut set = CpuSet::new();
    for &c in cpus {
        set.set(c);
    }
    sched_setaffinity(None, &set)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plan_takes_the_first_allowed_cpus_or_says_why_not() {
        let plan_of = |threads, cpus: &[usize]| plan(threads, Ok(cpus.to_vec()));
        assert_eq!(plan_of(2, &[2, 5]), Placement::Pinned { cpus: vec![2, 5] });
        assert_eq!(plan_of(2, &[2, 5]).cpu_of(1), Some(5));
        assert_eq!(plan_of(2, &[2, 5]).cpu_of(2), None);
        assert_eq!(plan_of(2, &[2, 5]).to_string(), "workers pinned to CPUs 2, 5");
        let few = plan_of(3, &[0, 1]);
        assert_eq!(few.cpu_of(0), None);
        assert_eq!(few.to_string(), "workers not pinned: 3 worker threads but only 2 usable CPUs");
        let many = plan_of(2, &[0, 1, 2, 3]);
        assert_eq!(many.cpu_of(0), None);
        assert!(
            many.to_string().contains("may run on 4 CPUs") && many.to_string().contains("taskset -c 2,3"),
            "{many}"
        );
        let failed = plan(1, Err(std::io::Error::other("no")));
        assert!(failed.to_string().contains("cannot read the process's CPU affinity"), "{failed}");
    }

    #[test]
    fn a_pinned_thread_runs_on_its_cpu_only() {
        let allowed = allowed_cpus().expect("the affinity mask");
        assert!(!allowed.is_empty());
        let cpu = *allowed.last().expect("a CPU");
        // A thread of its own: the test harness's thread keeps its mask.
        let (mask, running_on) = std::thread::spawn(move || {
            pin_current_thread(cpu).expect("pinning to an allowed CPU");
            (allowed_cpus().expect("the new mask"), rustix::thread::sched_getcpu())
        })
        .join()
        .expect("the pinned thread");
        assert_eq!(mask, vec![cpu]);
        assert_eq!(running_on, cpu);
    }
}
