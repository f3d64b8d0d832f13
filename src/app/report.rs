//! Small helpers for reports: percentiles, progress bars, and the rescue of outputs
//! that cannot be written at the end of a run.

use indicatif::{ProgressBar, ProgressStyle};

/// The `q`-quantile (0..=1) of `values` by the nearest-rank method; NaN if empty.
pub fn percentile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

/// How many recent samples of a time the long-running processes (the tracker, the pose
/// client) keep for their summaries: about an hour at 30 Hz.
pub const RECENT_SAMPLES: usize = 100_000;

/// Adds `value` as the sample numbered `index` (0, 1, … in the order they come) to
/// `samples`, which keep the most recent `cap`: once full, the oldest is overwritten
/// (no allocation, so a process left running keeps a bounded record).
pub fn push_recent(samples: &mut Vec<f64>, index: u64, cap: usize, value: f64) {
    if samples.len() < cap {
        samples.push(value);
    } else if let Some(slot) = samples.get_mut((index % cap.max(1) as u64) as usize) {
        *slot = value;
    }
}

/// A progress bar on a terminal (hidden when stderr is not one), after a line on stderr
/// that says what starts and how to stop it (see `app::interrupt`).
pub fn progress_bar(len: u64, what: &str) -> ProgressBar {
    let count = if len > 0 { format!(" {len} frames") } else { String::new() };
    log_line(format_args!("{what}{count} (Ctrl-C stops after the current frame and keeps what is done)"));
    let bar = ProgressBar::new(len);
    let style = ProgressStyle::with_template("{msg:12} [{bar:40}] {pos}/{len} frames  {per_sec}  eta {eta}")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
}

/// Writes a line to stderr, ignoring failure: a process that outlives its log reader
/// (a closed pipe) must keep running rather than panic as `eprintln!` would.
pub fn log_line(args: std::fmt::Arguments) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr().lock(), "{args}");
}

/// Writes a run's output to `path` with `write`. If that fails at the end of a run (the
/// disk filled up meanwhile, the folder was removed), the output is written into the
/// system's temporary folder instead and the error says where: the results of a long
/// run are not lost. (`app::outputs::check_outputs` catches the mistakes that are known
/// before it.)
pub fn write_or_rescue(
    path: &std::path::Path,
    write: impl Fn(&std::path::Path) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    write(path).map_err(|error| rescue(path, error, write))
}

/// After `error` writing the output named `path`, writes it with `write` into the
/// system's temporary folder ([`rescue_path`]): the error, saying where it went if it
/// could be written there.
pub fn rescue(
    path: &std::path::Path,
    error: anyhow::Error,
    write: impl Fn(&std::path::Path) -> anyhow::Result<()>,
) -> anyhow::Error {
    let rescue = rescue_path(path);
    if rescue != path && write(&rescue).is_ok() {
        let said = format!("could not write {}; it was written to {} instead", path.display(), rescue.display());
        return error.context(said);
    }
    error
}

/// Where an output named `path` is rescued to: `mrsmap-rescued-<pid>-<name>` in the
/// system's temporary folder.
pub fn rescue_path(path: &std::path::Path) -> std::path::PathBuf {
    let name = path.file_name().map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    std::env::temp_dir().join(format!("mrsmap-rescued-{}-{name}", std::process::id()))
}

/// [`write_or_rescue`] for a file of `bytes`, written whole or not at all
/// ([`crate::io::atomic::write_whole`]).
pub fn write_bytes_or_rescue(path: &std::path::Path, bytes: &[u8]) -> anyhow::Result<()> {
    use anyhow::Context as _;
    write_or_rescue(path, |p| {
        crate::io::atomic::write_whole(p, bytes).with_context(|| format!("writing {}", p.display()))
    })
}

/// The outcome of writing two outputs, each tried whatever became of the other: both
/// errors said when both failed.
pub fn both_written(first: anyhow::Result<()>, second: anyhow::Result<()>) -> anyhow::Result<()> {
    match (first, second) {
        (Err(a), Err(b)) => {
            // `a` may itself hold two (or more) failures: `b` joins them.
            let mut failed = a.downcast::<OutputsFailed>().unwrap_or_else(|a| OutputsFailed(vec![a]));
            failed.0.push(b);
            Err(failed.into())
        }
        (a, b) => a.and(b),
    }
}

/// Outputs that could not be written, in the order they were tried: each one's message,
/// then the first one's root cause (said once: a full disk fails them all alike).
#[derive(Debug)]
struct OutputsFailed(Vec<anyhow::Error>);

impl std::fmt::Display for OutputsFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (k, e) in self.0.iter().enumerate() {
            write!(f, "{}{e}", if k == 0 { "" } else { "\nand " })?;
        }
        if let Some(first) = self.0.first() {
            let cause = first.root_cause().to_string();
            if cause != first.to_string() {
                write!(f, "\n  caused by: {cause}")?;
            }
        }
        Ok(())
    }
}

impl std::error::Error for OutputsFailed {}

/// One line on how errors against ground truth compare with the published covariances of
/// `model` ("Eq. 6", "clustered"; docs/evaluation.md, "The pose covariance").
pub fn covariance_report(c: &crate::eval::consistency::Consistency, model: &str, what: &str) -> String {
    format!(
        "covariance ({model}) vs ground truth ({} {what}): the errors are {:.1}× its standard deviation \
         (translation alone {:.1}×; median NEES {:.1}, consistent 5.3); {:.0} % within its 95 % bound; \
         median translation error {:.2} mm against a predicted {:.2} mm",
        c.count,
        c.std_ratio(),
        c.std_ratio_translation(),
        c.median_nees,
        c.within_95 * 100.0,
        c.median_translation_error_m * 1e3,
        c.median_translation_std_m * 1e3
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recent_samples_keep_the_last_ones() {
        let mut samples = Vec::new();
        for i in 0..10u64 {
            push_recent(&mut samples, i, 4, i as f64);
        }
        samples.sort_by(f64::total_cmp);
        assert_eq!(samples, [6.0, 7.0, 8.0, 9.0]);
    }

    #[test]
    fn an_output_that_cannot_be_written_is_rescued_into_the_temporary_folder() {
        let lost = std::path::Path::new("/no/such/folder/model.mrsm");
        let write = |p: &std::path::Path| std::fs::write(p, b"results").map_err(anyhow::Error::from);
        let error = write_or_rescue(lost, write).expect_err("the folder does not exist");
        let rescued = std::env::temp_dir().join(format!("mrsmap-rescued-{}-model.mrsm", std::process::id()));
        assert!(error.to_string().contains(&format!("written to {} instead", rescued.display())), "{error}");
        assert_eq!(std::fs::read(&rescued).expect("rescued"), b"results");
        let _ = std::fs::remove_file(&rescued);
        // A good path is written and nothing else.
        let good = std::env::temp_dir().join(format!("mrsmap-write-{}.txt", std::process::id()));
        write_or_rescue(&good, write).expect("writes");
        assert!(good.exists() && !rescued.exists());
        let _ = std::fs::remove_file(&good);
    }

    #[test]
    fn two_outputs_are_each_tried_and_both_failures_said() {
        let fail = |what: &str| Err::<(), _>(anyhow::anyhow!("could not write {what}"));
        assert!(both_written(Ok(()), Ok(())).is_ok());
        assert_eq!(both_written(fail("a"), Ok(())).expect_err("a failed").to_string(), "could not write a");
        assert_eq!(both_written(Ok(()), fail("b")).expect_err("b failed").to_string(), "could not write b");
        let both = both_written(fail("a"), fail("b")).expect_err("both failed").to_string();
        assert_eq!(both, "could not write a\nand could not write b");
        // Three, with the first's cause said once, at the end.
        let io = std::io::Error::other("No space left on device");
        let a = Err(anyhow::Error::from(io).context("could not write a"));
        let three = both_written(both_written(a, fail("b")), fail("c")).expect_err("all failed").to_string();
        assert_eq!(
            three,
            "could not write a\nand could not write b\nand could not write c\n  caused by: No space left on device"
        );
    }
}
