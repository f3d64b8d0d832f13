//! No command writes over a file it reads, or writes two outputs into one file: a
//! mistyped path is refused before the run, naming the flag and the file, and the file
//! is left as it was. Every file at stake here is a copy in a temporary folder.

mod common;

use common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs `mrsmap` and returns its exit code and standard error.
fn code_and_stderr(args: &[&str]) -> (Option<i32>, String) {
    let out = mrsmap(args);
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// Asserts that the command failed before writing anything, with a message naming
/// `flag`, `path` and what the file is, and that `path` still holds `before`.
fn assert_refused(args: &[&str], flag: &str, path: &Path, what: &str, before: &[u8]) {
    let (code, err) = code_and_stderr(args);
    assert_eq!(code, Some(1), "{args:?}: {err}");
    let said = format!("{flag} {} is {what}, which this run reads", path.display());
    assert!(err.contains(&said), "{args:?}: expected `{said}` in: {err}");
    assert_eq!(std::fs::read(path).expect("still there"), before, "{args:?} changed {}", path.display());
}

/// A copy of the shipped model, and a tracker configuration for it, in `dir`.
fn model_and_config(dir: &Path, tag: &str) -> (PathBuf, PathBuf) {
    let model = dir.join("teddy.mrsm");
    std::fs::copy(root().join("models/teddy.mrsm"), &model).expect("copy the model");
    let text = tracker_config_text(tag, "")
        .replace(&root().join("models/teddy.mrsm").display().to_string(), &model.display().to_string());
    let config = dir.join("tracker.toml");
    std::fs::write(&config, text).expect("write config");
    (model, config)
}

#[test]
fn a_dataset_s_files_are_never_an_output() {
    let clip = copy_clip("outputs-dataset");
    let camera = fr3_camera_file();
    let gt = clip.join("groundtruth.txt");
    let gt_before = std::fs::read(&gt).expect("reads");
    let assoc = clip.join("associations.txt");
    let assoc_before = std::fs::read(&assoc).expect("reads");
    let (d, c) = (path_str(&clip), path_str(&camera));
    let what = "the dataset's groundtruth.txt";
    assert_refused(
        &["odometry", "--dataset", d, "--camera", c, "--out", path_str(&gt)],
        "--out",
        &gt,
        what,
        &gt_before,
    );
    // The same file by another spelling.
    let other = clip.join("rgb/../groundtruth.txt");
    let args = ["odometry", "--dataset", d, "--camera", c, "--out", "/dev/null", "--timings", path_str(&other)];
    assert_refused(&args, "--timings", &other, what, &gt_before);
    let args = ["map", "--dataset", d, "--camera", c, "--trajectory", path_str(&gt)];
    assert_refused(&args, "--trajectory", &gt, what, &gt_before);
    let args = ["convert", "tum-to-mcap", d, "--camera", c, "--out", path_str(&assoc), "--force"];
    assert_refused(&args, "--out", &assoc, "the dataset's associations.txt", &assoc_before);
    // The camera file too.
    let camera_copy = clip.join("camera.toml");
    std::fs::copy(&camera, &camera_copy).expect("copy");
    let camera_before = std::fs::read(&camera_copy).expect("reads");
    let args = ["odometry", "--dataset", d, "--camera", path_str(&camera_copy), "--out", path_str(&camera_copy)];
    assert_refused(&args, "--out", &camera_copy, "the camera file", &camera_before);
    // Two outputs in one file.
    let traj = clip.join("traj.txt");
    let (code, err) = code_and_stderr(&[
        "odometry",
        "--dataset",
        d,
        "--camera",
        c,
        "--out",
        path_str(&traj),
        "--timings",
        path_str(&traj),
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("--out and --timings name the same file"), "{err}");
    assert!(!traj.exists(), "nothing was written");
}

#[test]
fn a_recording_a_model_and_a_configuration_are_never_an_output() {
    let dir = temp_dir("outputs-replay");
    let (model, config) = model_and_config(&dir, "outputs");
    let rec = dir.join("rec.mcap");
    let (code, err) = code_and_stderr(&["convert", "tum-to-mcap", path_str(&teddy_clip()), "--out", path_str(&rec)]);
    assert_eq!(code, Some(0), "{err}");
    let rec_before = std::fs::read(&rec).expect("reads");
    let model_before = std::fs::read(&model).expect("reads");
    let config_before = std::fs::read(&config).expect("reads");
    let (r, cfg) = (path_str(&rec), path_str(&config));
    let poses = dir.join("poses.mcap");
    // --force allows replacing an older output, never an input.
    let args = ["replay", "--input", r, "--config", cfg, "--out", path_str(&poses), "--trajectory", r, "--force"];
    assert_refused(&args, "--trajectory", &rec, "the input recording", &rec_before);
    let args = ["replay", "--input", r, "--config", cfg, "--trajectory", path_str(&model)];
    assert_refused(&args, "--trajectory", &model, "the model of 'teddy'", &model_before);
    let args = ["replay", "--input", r, "--config", cfg, "--out", path_str(&config), "--force"];
    assert_refused(&args, "--out", &config, "the tracker configuration", &config_before);
    let (code, err) = code_and_stderr(&[
        "replay",
        "--input",
        r,
        "--config",
        cfg,
        "--out",
        path_str(&poses),
        "--trajectory",
        path_str(&poses),
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("--out and --trajectory name the same file"), "{err}");
    // The tracker over a dataset, and recording a live run.
    let (clip, camera) = (teddy_clip(), fr3_camera_file());
    let (d, c) = (path_str(&clip), path_str(&camera));
    let args = ["track", "--config", cfg, "--dataset", d, "--camera", c, "--trajectory", path_str(&model)];
    assert_refused(&args, "--trajectory", &model, "the model of 'teddy'", &model_before);
    let args = ["track", "--config", cfg, "--record", path_str(&config)];
    assert_refused(&args, "--record", &config, "the tracker configuration", &config_before);
    // A recording of an earlier live run is replaced only with --force.
    let earlier = dir.join("earlier.mcap");
    std::fs::copy(&rec, &earlier).expect("copy");
    let (code, err) =
        code_and_stderr(&["track", "--config", cfg, "--record", path_str(&earlier), "--idle-timeout", "1"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains(&format!("{} exists; pass --force to replace it", earlier.display())), "{err}");
    assert_eq!(std::fs::read(&earlier).expect("still there"), rec_before);
    // So is what a crash left of one (`NAME.partial`).
    let (fresh, crashed) = (dir.join("fresh.mcap"), dir.join("fresh.mcap.partial"));
    std::fs::copy(&rec, &crashed).expect("copy");
    let (code, err) = code_and_stderr(&["track", "--config", cfg, "--record", path_str(&fresh), "--idle-timeout", "1"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains(&format!("{} exists: a recording that a crash left", crashed.display())), "{err}");
    assert_eq!(std::fs::read(&crashed).expect("still there"), rec_before);
    // A model's picture, and an evaluation's plot.
    let args = ["model", "render", path_str(&model), "--out", path_str(&model)];
    assert_refused(&args, "--out", &model, "the model file", &model_before);
    let gt = dir.join("gt.txt");
    std::fs::copy(teddy_clip().join("groundtruth.txt"), &gt).expect("copy");
    let gt_before = std::fs::read(&gt).expect("reads");
    for metric in ["rpe", "ate"] {
        let args = ["eval", metric, path_str(&gt), path_str(&gt), "--plot", path_str(&gt)];
        assert_refused(&args, "--plot", &gt, "the reference trajectory", &gt_before);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// An output named through a symbolic link is written into the file the link names
/// (the link stays); one named by a device or pipe (`/dev/stdout`) is written to, never
/// replaced by a regular file; an MCAP output, written with seeks, must be a file.
#[cfg(unix)]
#[test]
fn outputs_go_through_links_into_files_and_into_devices_as_they_are() {
    let dir = temp_dir("outputs-links");
    std::fs::create_dir(dir.join("results")).expect("a folder");
    let (file, link) = (dir.join("results/run1.txt"), dir.join("traj.txt"));
    std::fs::write(&file, "old").expect("writes");
    std::os::unix::fs::symlink(&file, &link).expect("a symbolic link");
    let (clip, camera) = (teddy_clip(), fr3_camera_file());
    let (d, c) = (path_str(&clip), path_str(&camera));
    let (code, err) = code_and_stderr(&["odometry", "--dataset", d, "--camera", c, "--out", path_str(&link)]);
    assert_eq!(code, Some(0), "{err}");
    assert!(std::fs::symlink_metadata(&link).expect("exists").file_type().is_symlink(), "the link stays a link");
    let written = std::fs::read_to_string(&file).expect("reads");
    assert!(written.starts_with("# mrsmap odometry") && written.lines().count() > 8, "{written}");
    // Standard output: the trajectory, and a picture, piped on.
    let out = mrsmap(&["odometry", "--dataset", d, "--camera", c, "--out", "/dev/stdout"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let poses = text.lines().filter(|l| l.split(' ').filter(|v| v.parse::<f64>().is_ok()).count() == 8).count();
    assert!(text.contains("# mrsmap odometry") && poses == 8, "{text}");
    let model = root().join("models/teddy.mrsm");
    let out = mrsmap(&["model", "render", path_str(&model), "--out", "/dev/stdout"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.stdout.starts_with(b"\x89PNG\r\n\x1a\n"), "a PNG on standard output");
    assert!(std::fs::symlink_metadata("/dev/stdout").expect("exists").file_type().is_symlink());
    // A recording cannot go to a device.
    let (code, err) = code_and_stderr(&["convert", "tum-to-mcap", d, "--out", "/dev/null", "--force"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("--out /dev/null") && err.contains("not a regular file"), "{err}");
    assert!(!std::fs::metadata("/dev/null").expect("exists").is_file(), "/dev/null is still a device");
}

#[test]
fn track_dataset_draws_each_tracked_frame_with_its_model() {
    let dir = temp_dir("overlay");
    let config = write_tracker_config(&dir, "overlay", "");
    let (clip, camera) = (teddy_clip(), fr3_camera_file());
    let pictures = dir.join("pictures");
    let args = ["track", "--config", path_str(&config), "--dataset", path_str(&clip), "--camera", path_str(&camera)];
    let out = Command::new(mrsmap_bin())
        .args(args)
        .args(["--max-frames", "3", "--start-at-ground-truth", "--overlay", path_str(&pictures)])
        .output()
        .expect("binary runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("3 frames tracking") && stdout.contains("3 pictures written"), "{stdout}");
    let mut names: Vec<String> = std::fs::read_dir(&pictures)
        .expect("the folder")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let depth_stamps: Vec<String> = std::fs::read_to_string(clip.join("associations.txt"))
        .expect("associations")
        .lines()
        .filter(|l| !l.starts_with('#'))
        .take(3)
        .map(|l| format!("{}.overlay.png", l.split_whitespace().nth(2).expect("depth stamp")))
        .collect();
    assert_eq!(names, depth_stamps, "one picture per frame, named by its depth stamp");
    let mut reader = mrsmap::io::image::PngReader::default();
    let mut rgb = Vec::new();
    reader.read_rgb8(&pictures.join(&names[0]), (640, 480), &mut rgb).expect("a VGA picture");
    let count = |c: [u8; 3]| rgb.chunks_exact(3).filter(|p| *p == c).count();
    let (green, red) = (count([40, 220, 60]), count([235, 40, 40]));
    // Tracked: a green frame, and the model drawn mostly where the depth agrees with it.
    assert_eq!(&rgb[..3], &[40, 220, 60]);
    let border = 2 * 4 * (640 + 480) - 4 * 16;
    assert!(green > border + 2000 && red < (green - border) / 10, "{green} green, {red} red pixels");
}
