//! Ctrl-C and SIGTERM for the offline commands (`odometry`, `map`, `track --dataset`,
//! `replay`, `convert`): hours of work are not thrown away because someone pressed
//! Ctrl-C.
//!
//! The first request stops the frame loop before its next frame; the command then
//! writes what it has — a trajectory of the frames processed, a finished MCAP file, a
//! model of the key views so far — notes the interruption in its outputs and exits with
//! status 130 (128 + SIGINT). A second request ends the process at once (status 130).
//! The live processes (`camera`, `track`, `poses`) handle the same signals through
//! iceoryx2 (`io::ipc::node`).

use anyhow::{Context, Result};
use signal_hook::consts::signal::{SIGINT, SIGTERM};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Exit status of a command that a request stopped early (128 + SIGINT, as shells do).
pub const INTERRUPTED_EXIT: u8 = 130;

/// A request to stop, shared between whoever asks (a signal handler, another thread)
/// and the frame loop that checks it before each frame.
#[derive(Debug, Clone, Default)]
pub struct Stop {
    flag: Arc<AtomicBool>,
    /// Checks left before the stop requests itself ([`Stop::after_frames`]).
    countdown: Option<Arc<AtomicUsize>>,
}

impl Stop {
    /// A stop that only [`Stop::request`] triggers.
    pub fn new() -> Self {
        Stop::default()
    }

    /// A stop that requests itself when the loop is about to start frame `frames + 1`:
    /// an interrupt at a known point (tests, or code that embeds a command with a work
    /// budget). Unlike `--max-frames`, the run is reported as interrupted.
    pub fn after_frames(frames: usize) -> Self {
        Stop { countdown: Some(Arc::new(AtomicUsize::new(frames))), ..Stop::default() }
    }

    /// A stop triggered by SIGINT or SIGTERM; a second signal ends the process at once.
    pub fn on_signals() -> Result<Self> {
        let stop = Stop::new();
        for signal in [SIGINT, SIGTERM] {
            // The order matters: the shutdown checks the flag before the flag is set, so
            // it fires only from the second signal on.
            signal_hook::flag::register_conditional_shutdown(signal, INTERRUPTED_EXIT.into(), Arc::clone(&stop.flag))
                .and_then(|_| signal_hook::flag::register(signal, Arc::clone(&stop.flag)))
                .with_context(|| format!("installing the handler of signal {signal}"))?;
        }
        Ok(stop)
    }

    /// Asks the loop to stop before its next frame.
    pub fn request(&self) {
        self.flag.store(true, Ordering::Relaxed);
    }

    /// Before frame `index` (from 0) of `of`: the interruption, if a stop was asked for.
    pub fn before_frame(&self, index: usize, of: Option<usize>) -> Option<Interrupted> {
        self.requested().then_some(Interrupted { after: index, of })
    }

    /// Whether a stop was asked for; the frame loops ask once before each frame.
    pub fn requested(&self) -> bool {
        if let Some(left) = &self.countdown
            && left.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1)).is_err()
        {
            self.request();
        }
        self.flag.load(Ordering::Relaxed)
    }
}

/// How far an interrupted run got, for its outputs and its report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Interrupted {
    /// Frames taken before the stop.
    pub after: usize,
    /// Frames the run would have taken, where known before the end.
    pub of: Option<usize>,
}

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.of {
            Some(of) => write!(f, "interrupted after {} of {of} frames", self.after),
            None => write!(f, "interrupted after {} frames", self.after),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_is_seen_by_every_clone() {
        let stop = Stop::new();
        let seen_by_loop = stop.clone();
        assert!(!seen_by_loop.requested());
        stop.request();
        assert!(seen_by_loop.requested());
    }

    #[test]
    fn after_frames_lets_that_many_frames_start() {
        let stop = Stop::after_frames(2);
        assert_eq!(
            [stop.requested(), stop.requested(), stop.requested(), stop.requested()],
            [false, false, true, true]
        );
        assert!(Stop::after_frames(0).requested());
    }
}
