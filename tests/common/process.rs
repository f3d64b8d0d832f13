//! Running `mrsmap` subcommands as processes: their stderr as lines, their exit, signals.

use super::{ChildGuard, mrsmap_bin};
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::Duration;

/// Starts `mrsmap ARGS`, forwarding its stderr lines to a channel.
pub fn start(args: &[&str]) -> (ChildGuard, Receiver<String>) {
    let mut child = Command::new(mrsmap_bin())
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mrsmap starts");
    let stderr = child.stderr.take().expect("stderr");
    let (tx, rx) = channel();
    std::thread::spawn(move || {
        // Keep draining even when nobody listens: a closed pipe would fail the child.
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    (ChildGuard(child), rx)
}

/// Waits for a stderr line containing `needle`.
pub fn wait_for(rx: &Receiver<String>, needle: &str, seconds: u64) -> Vec<String> {
    let mut seen = Vec::new();
    let deadline = std::time::Instant::now() + Duration::from_secs(seconds);
    while let Some(left) = deadline.checked_duration_since(std::time::Instant::now()) {
        match rx.recv_timeout(left) {
            Ok(line) => {
                let done = line.contains(needle);
                seen.push(line);
                if done {
                    return seen;
                }
            }
            Err(_) => break,
        }
    }
    panic!("no line with {needle:?} within {seconds} s; saw {seen:?}");
}

/// Sends signal `name` (e.g. `INT`) to the process.
pub fn signal(child: &Child, name: &str) {
    let ok = Command::new("kill").args([&format!("-{name}"), &child.id().to_string()]).status().expect("kill runs");
    assert!(ok.success());
}

/// Waits for the process to exit; returns (exit code, stdout).
pub fn finish(mut guard: ChildGuard, seconds: u64) -> (Option<i32>, String) {
    let deadline = std::time::Instant::now() + Duration::from_secs(seconds);
    loop {
        if let Some(status) = guard.0.try_wait().expect("wait") {
            let mut out = String::new();
            if let Some(mut stdout) = guard.0.stdout.take() {
                let _ = std::io::Read::read_to_string(&mut stdout, &mut out);
            }
            return (status.code(), out);
        }
        assert!(std::time::Instant::now() < deadline, "process did not exit within {seconds} s");
        std::thread::sleep(Duration::from_millis(50));
    }
}
