//! The `mrsmap` binary: help, exit codes, the odometry and eval commands end to end.

mod common;

use common::*;
use std::process::Command;

#[test]
fn help_teaches_the_commands() {
    let out = mrsmap(&["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for word in
        ["demo", "camera", "track", "poses", "detect", "replay", "convert", "odometry", "map", "model", "eval", "bench"]
    {
        assert!(text.contains(word), "{text}");
    }
    let out = mrsmap(&["odometry", "--help"]);
    let text = String::from_utf8_lossy(&out.stdout);
    for word in ["--dataset", "--camera", "--qvga", "--timings", "depth"] {
        assert!(text.contains(word), "{text}");
    }
}

#[test]
fn odometry_then_eval_end_to_end() {
    let dir = temp_dir("cli");
    let (traj, timings) = (dir.join("traj.txt"), dir.join("timings.csv"));
    let clip = teddy_clip();
    let out = mrsmap(&[
        "odometry",
        "--dataset",
        clip.to_str().expect("utf-8"),
        "--camera",
        fr3_camera_file().to_str().expect("utf-8"),
        "--out",
        traj.to_str().expect("utf-8"),
        "--timings",
        timings.to_str().expect("utf-8"),
        "--threads",
        "2",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("8 frames, 7 registered") && text.contains("RPE"), "{text}");
    // The registrations' covariances against the ground truth's motion: Eq. (6)
    // understates the errors on real frames (docs/evaluation.md, "The pose covariance").
    // The clustered covariance is never below Eq. (6), so the errors are fewer of its
    // standard deviations.
    let ratio = |model: &str| -> f64 {
        let needle = format!("covariance ({model}) vs ground truth (7 frame-to-frame");
        let cov = text.lines().find(|l| l.contains(&needle));
        let cov = cov.unwrap_or_else(|| panic!("no {model} covariance line: {text}"));
        cov.split("the errors are ").nth(1).and_then(|r| r.split('×').next()).expect(cov).parse().expect(cov)
    };
    let (eq6, clustered) = (ratio("Eq. 6"), ratio("clustered"));
    assert!(eq6 > 2.0 && eq6 < 100.0, "{text}");
    assert!(clustered > 0.0 && clustered <= eq6, "{text}");
    let csv = std::fs::read_to_string(&timings).expect("timings");
    assert_eq!(csv.lines().next(), Some("stamp,build_ms,register_ms,associations,iterations"));
    assert_eq!(csv.lines().count(), 9);
    let gt = clip.join("groundtruth.txt");
    for metric in ["rpe", "ate"] {
        let plot = dir.join(format!("{metric}.svg"));
        let out = mrsmap(&["eval", metric, path_str(&gt), path_str(&traj), "--plot", path_str(&plot)]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("median") && text.contains("rmse"), "{text}");
        // The picture: one SVG document, its errors in mm with the median printed above.
        let svg = std::fs::read_to_string(&plot).expect("plot written");
        let median_mm = text.lines().find_map(|l| l.trim().strip_prefix("median")).expect("median line");
        let median_mm: f64 = median_mm.trim().trim_end_matches("mm").trim().parse().expect("number");
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains(&format!("median {median_mm:.2}")), "{metric}: median {median_mm} not in the plot");
        assert!(!svg.contains("NaN"));
    }
}

#[test]
fn errors_exit_non_zero_and_name_the_problem() {
    let out = mrsmap(&["odometry", "--dataset", "x"]);
    assert_eq!(out.status.code(), Some(2), "usage errors exit with 2");
    let out = mrsmap(&[
        "odometry",
        "--dataset",
        teddy_clip().to_str().expect("utf-8"),
        "--camera",
        "/no/such/camera.toml",
        "--out",
        "/tmp/x.txt",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/no/such/camera.toml"));
    // One line per cause, each said once, and no backtrace even where the user's shell
    // asks for backtraces of panics.
    let out = Command::new(env!("CARGO_BIN_EXE_mrsmap"))
        .args(["track", "--config", "/no/such/tracker.toml"])
        .env("RUST_BACKTRACE", "1")
        .output()
        .expect("binary runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.starts_with("error: cannot read tracker config /no/such/tracker.toml"), "{err}");
    assert_eq!(err.matches("No such file").count(), 1, "{err}");
    assert!(!err.contains("backtrace"), "{err}");
    // The demo's default paths are relative to the repository: elsewhere it says so.
    let out = Command::new(env!("CARGO_BIN_EXE_mrsmap"))
        .arg("demo")
        .current_dir(std::env::temp_dir())
        .output()
        .expect("binary runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("repository's root folder") && err.contains("--config"), "{err}");
    // A frame delta of 0 is a usage error (it used to panic in the RPE's stepping).
    let gt = teddy_clip().join("groundtruth.txt");
    let out = mrsmap(&["eval", "rpe", path_str(&gt), path_str(&gt), "--delta", "0"]);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--delta"));
}

#[test]
fn bad_paths_and_settings_are_refused_before_any_work() {
    // A missing recording is named as such (it used to be taken for the output file,
    // which did not exist either).
    let dir = temp_dir("cli-replay-missing");
    let config = root().join("robot_config/tracker.toml");
    let poses = dir.join("poses.mcap");
    let out =
        mrsmap(&["replay", "--input", "/no/such/rec.mcap", "--config", path_str(&config), "--out", path_str(&poses)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("cannot open /no/such/rec.mcap") && !err.contains("is the input recording"), "{err}");
    // A ground truth that cannot be read is named, with the line at fault, before the
    // recording is opened.
    let bad_truth = dir.join("truth.txt");
    std::fs::write(&bad_truth, "1341841873.27 0 0 1\n").expect("write");
    let args = ["replay", "--input", "/no/such/rec.mcap", "--config", path_str(&config), "--groundtruth"];
    let out = mrsmap(&[&args[..], &[path_str(&bad_truth)]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.starts_with("error: --groundtruth ") && err.contains("truth.txt:1: expected 8 fields"), "{err}");
    // A missing dataset is said as such (before its camera is guessed from its name).
    let out = mrsmap(&["convert", "tum-to-mcap", "/no/such/dataset", "--out", path_str(&dir.join("c.mcap"))]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("opening dataset /no/such/dataset") && !err.contains("cannot tell the camera"), "{err}");
    // Outputs that cannot be written are refused before the run, not after it (a
    // model built over minutes would be lost at the end).
    let clip = teddy_clip();
    let camera = fr3_camera_file();
    let object = root().join("robot_config/objects/teddy.toml");
    let (clip, camera, object) = (path_str(&clip), path_str(&camera), path_str(&object));
    let lost = "/no/such/folder/out.txt";
    for (args, flag) in [
        (vec!["map", "--dataset", clip, "--camera", camera, "--object", object, "--out", lost], "--out"),
        (vec!["map", "--dataset", clip, "--camera", camera, "--trajectory", lost], "--trajectory"),
        (
            vec![
                "odometry",
                "--dataset",
                clip,
                "--camera",
                camera,
                "--out",
                path_str(&dir.join("o.txt")),
                "--timings",
                lost,
            ],
            "--timings",
        ),
        (
            vec![
                "track",
                "--config",
                path_str(&config),
                "--dataset",
                clip,
                "--camera",
                camera,
                "--trajectory",
                path_str(&dir),
            ],
            "--trajectory",
        ),
        (
            vec!["replay", "--input", "/no/such/rec.mcap", "--config", path_str(&config), "--trajectory", lost],
            "--trajectory",
        ),
        (vec!["poses", "--out", lost], "--out"),
    ] {
        let out = mrsmap(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.starts_with(&format!("error: {flag} ")) && err.contains("cannot write there"), "{args:?}: {err}");
        assert!(!err.contains("frames (Ctrl-C"), "{args:?} ran before refusing: {err}");
    }
    // The quality measurement refuses settings that would make its table meaningless
    // (no registrations: precision and recall of 1 by convention) or that its run
    // cannot have.
    let quality = ["eval", "tracking-quality", "--config", path_str(&config), "--dataset", clip, "--camera", camera];
    for (extra, says) in [
        (vec!["--first-frame", "0", "--fail-mm", "nan"], "--fail-mm must be a finite number"),
        (vec!["--max-shift=-0.1"], "--max-shift must be a finite number"),
        (vec!["--first-frame", "6"], "needs at least 3 frames"),
    ] {
        let args: Vec<&str> = quality.iter().copied().chain(extra.iter().copied()).collect();
        let out = mrsmap(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.code() == Some(1) && err.contains(says), "{extra:?}: {err}");
    }
    // The benchmark reads its tracker configuration before its odometry runs.
    let out = mrsmap(&["bench", "--dataset", clip, "--camera", camera, "--tracking-config", "/no/such/tracker.toml"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/no/such/tracker.toml") && !String::from_utf8_lossy(&out.stdout).contains("| VGA"), "{err}");
    // A picture that cannot be written is said to be so (it was "cannot read"), before
    // the model is drawn.
    let model = root().join("models/teddy.mrsm");
    let out = mrsmap(&["model", "render", path_str(&model), "--out", "/no/such/folder/teddy.png"]);
    let err = String::from_utf8_lossy(&out.stderr);
    let said = "--out /no/such/folder/teddy.png: cannot write there: folder /no/such/folder does not exist";
    assert!(err.contains(said) && !err.contains("cannot read"), "{err}");
    // A view that is not a number (it drew an empty picture of "11115 surfels").
    let out =
        mrsmap(&["model", "render", path_str(&model), "--out", path_str(&dir.join("m.png")), "--distance", "nan"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.code() == Some(1) && err.contains("--distance must be a finite number"), "{err}");
    // A folder is not read as a file that lacks MCAP's magic bytes.
    let out = mrsmap(&["replay", "--input", path_str(&dir), "--config", path_str(&config), "--out", path_str(&poses)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("cannot open {}", dir.display())) && !err.contains("magic"), "{err}");
}

#[test]
fn zero_counts_and_empty_service_names_are_refused() {
    // `--max-frames 0` used to run nothing and report it (replay: "0 tracked"; the live
    // tracker: waiting for frames it would not track); an empty service prefix put the
    // driver on a bare "/rgbd/vga".
    let config = root().join("robot_config/tracker.toml");
    let config = path_str(&config);
    for (args, flag, says) in [
        (vec!["replay", "--input", "r.mcap", "--config", config, "--max-frames", "0"], "--max-frames", "at least 1"),
        (vec!["track", "--config", config, "--max-frames", "0"], "--max-frames", "at least 1"),
        (vec!["camera", "--dataset", "d", "--camera", "c", "--max-frames", "0"], "--max-frames", "at least 1"),
        (
            vec!["odometry", "--dataset", "d", "--camera", "c", "--out", "o", "--max-frames", "0"],
            "--max-frames",
            "at least 1",
        ),
        (vec!["poses", "--count", "0"], "--count", "at least 1"),
        (vec!["replay", "--input", "r.mcap", "--config", config, "--every", "0"], "--every", "at least 1"),
        (vec!["replay", "--input", "r.mcap", "--config", config, "--threads", "0"], "--threads", "at least 1"),
        (vec!["map", "--dataset", "d", "--camera", "c", "--threads", "0"], "--threads", "at least 1"),
        (vec!["bench", "--dataset", "d", "--camera", "c", "--passes", "0"], "--passes", "at least 1"),
        (vec!["convert", "tum-to-mcap", "d", "--out", "o", "--chunk-size", "0"], "--chunk-size", "at least 1"),
        // A chunk the replay could not read back (records over 256 MiB are refused).
        (
            vec!["convert", "tum-to-mcap", "d", "--out", "o", "--chunk-size", "1000000000"],
            "--chunk-size",
            "at most 67108864",
        ),
        (
            vec!["eval", "tracking-quality", "--config", config, "--dataset", "d", "--camera", "c", "--trials", "0"],
            "--trials",
            "at least 1",
        ),
        (vec!["camera", "--dataset", "d", "--camera", "c", "--service", ""], "--service", "must not be empty"),
        (vec!["track", "--config", config, "--poses-service", " "], "--poses-service", "must not be empty"),
    ] {
        let out = mrsmap(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(&format!("for '{flag} ")) && err.contains(says), "{args:?}: {err}");
    }
}

#[test]
fn a_detection_is_checked_before_it_is_sent() {
    let id = format!("mrsmap_test_{}_detect_cli", std::process::id());
    let (detections, poses) = (format!("{id}/detections"), format!("{id}/poses"));
    let at = |pose: &[&str], object: &str| {
        let mut args = vec!["detect", "--object", object, "--service", &detections, "--poses", &poses, "--pose"];
        args.extend(pose);
        let out = mrsmap(&args);
        (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    let (code, err) = at(&["0", "0", "1", "0", "0", "0", "2"], "teddy");
    assert!(code == Some(1) && err.contains("--pose") && err.contains("norm 2.0000"), "{err}");
    let (code, err) = at(&["0", "0", "NaN", "0", "0", "0", "1"], "teddy");
    assert!(code == Some(1) && err.contains("not finite"), "{err}");
    let (code, err) = at(&["0", "0", "1", "0", "0", "0", "1"], &"x".repeat(32));
    assert!(code == Some(1) && err.contains("1 to 31 bytes"), "{err}");
    let (code, err) = at(&["0", "0", "1", "0", "0", "0", "1"], "teddy");
    assert!(code == Some(1) && err.contains(&format!("no tracker publishes poses on {poses}")), "{err}");
    let (code, err) = at(&["0", "0", "1", "0", "0"], "teddy");
    assert!(code == Some(2) && err.contains("7 values required"), "{err}");
}

#[test]
fn a_report_into_a_closed_pipe_ends_quietly() {
    // `mrsmap eval … | head -0`: the reader is gone before the first line. The process is
    // ended by SIGPIPE as a Unix tool is, without a panic message.
    use std::os::unix::process::ExitStatusExt;
    let gt = teddy_clip().join("groundtruth.txt");
    let mut child = Command::new(env!("CARGO_BIN_EXE_mrsmap"))
        .args(["eval", "rpe", path_str(&gt), path_str(&gt)])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("binary runs");
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("waits");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(out.status.signal() == Some(13) || out.status.success(), "{:?}: {err}", out.status);
}

#[test]
fn eval_offset_shifts_the_estimate_stamps() {
    // The ground truth as its own estimate, 1000 s late: nothing associates without an
    // offset; with `--offset -1000` every pose pairs with itself and the errors are zero.
    let dir = temp_dir("cli-offset");
    let gt = teddy_clip().join("groundtruth.txt");
    let late = dir.join("late.txt");
    let text = std::fs::read_to_string(&gt).expect("ground truth");
    let shifted: String = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let (stamp, rest) = l.split_once(' ').expect("stamped line");
            format!("{:.6} {rest}\n", stamp.parse::<f64>().expect("stamp") + 1000.0)
        })
        .collect();
    std::fs::write(&late, shifted).expect("write");
    for metric in ["ate", "rpe"] {
        let out = mrsmap(&["eval", metric, path_str(&gt), path_str(&late)]);
        assert!(!out.status.success(), "{metric}: no stamp is within 0.02 s without the offset");
        let out = mrsmap(&["eval", metric, path_str(&gt), path_str(&late), "--offset", "-1000"]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("rmse   0.0000 mm"), "{metric}: {text}");
    }
    // Poses out of time order are paired as they come (as evo does), and said.
    let reversed = dir.join("reversed.txt");
    std::fs::write(&reversed, text.lines().rev().map(|l| format!("{l}\n")).collect::<String>()).expect("write");
    let out = mrsmap(&["eval", "rpe", path_str(&gt), path_str(&reversed)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && err.contains("reversed.txt: pose 2 (stamp ") && err.contains("as evo does"),
        "{err}"
    );
    assert!(!err.contains("groundtruth.txt: pose"), "the ground truth is in order: {err}");
    let out = mrsmap(&["eval", "ate", path_str(&gt), path_str(&late), "--offset", "inf"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--offset must be a finite number"));
}
