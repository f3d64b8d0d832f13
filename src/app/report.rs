//! Small helpers for reports: percentiles and progress bars.

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
