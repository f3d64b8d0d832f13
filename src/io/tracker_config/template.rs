//! The whole tracker configuration with every key at its default, each explained
//! (`mrsmap track --print-default-config`). The values come from the code's defaults,
//! so the text cannot fall behind them; `robot_config/tracker.toml` is this text (a
//! test compares them).

use super::{DEFAULT_MAX_AGE_S, DEFAULT_PIN_THREADS, DEFAULT_SIZE};
use crate::io::ipc::{DEFAULT_CAMERA_SERVICE, DETECTIONS_SERVICE, POSES_SERVICE};
use crate::registration::ColorTerm;
use crate::tracking::TrackerParams;
use std::fmt::Write;

/// The column at which a key's comment starts when the key and its value leave room.
const COMMENT_COLUMN: usize = 33;

/// Comment lines longer than this go above their key, not beside it.
const BESIDE_MAX_CHARS: usize = 70;

/// One key of the file: its name, its value as TOML, whether the line is commented out
/// (a key whose default is to be absent, shown with an example value) and what it
/// does, a line per line of comment.
struct Key {
    name: &'static str,
    value: String,
    commented_out: bool,
    comment: &'static [&'static str],
}

fn key(name: &'static str, value: impl TomlValue, comment: &'static [&'static str]) -> Key {
    Key { name, value: value.toml(), commented_out: false, comment }
}

/// A value as TOML writes it.
trait TomlValue {
    fn toml(&self) -> String;
}

impl TomlValue for f64 {
    fn toml(&self) -> String {
        // `{:?}` always writes a decimal point or an exponent, as TOML floats need.
        format!("{self:?}")
    }
}

impl TomlValue for bool {
    fn toml(&self) -> String {
        self.to_string()
    }
}

impl TomlValue for usize {
    fn toml(&self) -> String {
        self.to_string()
    }
}

impl TomlValue for u32 {
    fn toml(&self) -> String {
        self.to_string()
    }
}

impl TomlValue for &str {
    fn toml(&self) -> String {
        format!("{self:?}")
    }
}

impl TomlValue for [f64; 7] {
    fn toml(&self) -> String {
        let values: Vec<String> = self.iter().map(|v| v.to_string()).collect();
        format!("[{}]", values.join(", "))
    }
}

/// The file's opening lines.
const HEADER: &[&str] = &[
    "The tracker process (`mrsmap track --config robot_config/tracker.toml`).",
    "Keys are the names of the fields they set. Every key but the objects' may be left out:",
    "the values written here are the defaults. `mrsmap track --print-default-config` prints",
    "this file (robot_config/tracker.toml is its output).",
];

/// The example object: the teddy bear of the clip the repository ships.
const TEDDY_CAMERA_FROM_OBJECT: [f64; 7] = [0.1923, 0.1253, 1.0402, -0.25098, -0.79599, 0.53327, -0.13797];

/// The sections of the file in order: its header line, the comment above it, its keys.
fn sections() -> Vec<(&'static str, &'static [&'static str], Vec<Key>)> {
    let p = TrackerParams::default();
    vec![
        (
            "[camera]",
            &[][..],
            vec![
                key(
                    "service",
                    DEFAULT_CAMERA_SERVICE,
                    &[
                        "the camera driver's service prefix (`mrsmap camera --service`);",
                        "frames arrive on \"<service>/rgbd/vga\" or \"<service>/rgbd/qvga\"",
                    ],
                ),
                key("size", DEFAULT_SIZE, &["\"vga\" (640x480) or \"qvga\" (320x240)"]),
            ],
        ),
        (
            "[poses]",
            &[],
            vec![key("service", POSES_SERVICE, &["where poses are published (`mrsmap poses --service`)"])],
        ),
        (
            "[detections]",
            &[
                "Where an external detector sends detections (`mrsmap detect`; the message is",
                "MrsmapObjectDetection, docs/wire-format.md): a detected object is re-initialised at the",
                "detected pose, by default only when it is lost or initialising.",
            ],
            vec![
                key("service", DETECTIONS_SERVICE, &["must differ from poses.service"]),
                key("max_age_s", DEFAULT_MAX_AGE_S, &["detections from frames older than this are ignored"]),
            ],
        ),
        ("[tracker]", &[], tracker_keys(&p)),
        (
            "[[object]]",
            &[
                "One [[object]] table per object to track. This one is the teddy bear of the clip",
                "the repository ships (tests/data/fr3_teddy_8).",
            ],
            vec![
                key("name", "teddy", &["1 to 31 bytes, unique: poses and trajectory files carry it"]),
                key("model", "../models/teddy.mrsm", &["relative to this file"]),
                key(
                    "camera_from_object",
                    TEDDY_CAMERA_FROM_OBJECT,
                    &[
                        "Where the object is expected when tracking starts: the pose of the object frame in the",
                        "camera's optical frame (x right, y down, z forward), tx ty tz (m) qx qy qz qw.",
                        "This one is the teddy in the first frame of tests/data/fr3_teddy_8 (from the TUM",
                        "ground truth and the model's world_from_model). `mrsmap track --check` says where a",
                        "start pose puts its object, and warns when that is out of the camera's view.",
                    ],
                ),
                key(
                    "search_translation_m",
                    0.05,
                    &[
                        "When (re-)initialising, also try the pose shifted by this much along each camera axis",
                        "(default 0: that pose alone) ...",
                    ],
                ),
                key("search_yaw_deg", 20.0, &["... and turned by this much about the object's up axis (default 0)"]),
                key(
                    "color_term",
                    false,
                    &[
                        "true: the registration also compares colours (not in the paper, which compares",
                        "positions only), for objects whose shape leaves a turn free that their print",
                        "shows: on a rendered 7 cm bottle ATE median 67 -> 17 mm. It costs accuracy",
                        "where the shape fixes the pose: on the teddy (real frames) 7.0 -> 8.8 mm",
                        "(docs/evaluation.md, \"The colour term\")",
                    ],
                ),
                Key {
                    name: "color_luminance_std",
                    value: 0.1.toml(),
                    commented_out: true,
                    comment: &[
                        "with color_term: standard deviation of a luminance residual (default inf: not compared)",
                    ],
                },
                Key {
                    name: "color_chroma_std",
                    value: ColorTerm::default().chroma_std.toml(),
                    commented_out: true,
                    comment: &["... and of a chroma one (default 0.03); larger: a weaker colour term"],
                },
            ],
        ),
    ]
}

/// The keys of `[tracker]`.
fn tracker_keys(p: &TrackerParams) -> Vec<Key> {
    let mut keys = worker_keys();
    keys.extend(scene_map_keys(p));
    keys.extend(tracking_keys(p));
    keys.extend(registration_keys(p));
    keys
}

/// The keys of `[tracker]` on the worker threads.
fn worker_keys() -> Vec<Key> {
    vec![
        Key {
            name: "threads",
            value: 2usize.toml(),
            commented_out: true,
            comment: &["worker threads (absent: one per core the process may use)"],
        },
        key(
            "pin_threads",
            DEFAULT_PIN_THREADS,
            &[
                "each worker on a CPU of its own when they are as many as the CPUs",
                "the process may use (choose them: `taskset -c 2,3 mrsmap track ...`).",
                "Unpinned, the second worker woken after the idle gap between",
                "frames can land on the busy core: live VGA frames took 1.5x as",
                "long (docs/benchmarks.md, \"The live tracker after an idle gap\")",
            ],
        ),
    ]
}

/// The keys of `[tracker]` on the scene map (§3, §5.2).
fn scene_map_keys(p: &TrackerParams) -> Vec<Key> {
    vec![
        key("lambda", p.map.lambda, &["scene maps: finest cell at range r is about 2·λ·r² (paper §3.3)"]),
        key(
            "small_objects_on_one_level",
            p.small_objects_on_one_level,
            &[
                "an object whose visible surface spans less than a factor 1.41 in",
                "range goes into its scene map all on one level, the finer of the two",
                "its points round to (λ at most halved); large objects never are. On",
                "the rendered cow and Suzanne it keeps them tracked (docs/evaluation.md)",
            ],
        ),
        key(
            "scene_min_points_by_image_size",
            p.scene_min_points_by_image_size,
            &[
                "a scene surfel needs the paper's 10 points in a VGA image, fewer in",
                "a smaller one (the same cell holds fewer pixels), not below 5: 5 at",
                "QVGA. On rendered small objects at QVGA it keeps the cow tracked",
                "(docs/evaluation.md, \"Small objects at QVGA\")",
            ],
        ),
        key(
            "gate_mahalanobis2",
            p.gate_mahalanobis2,
            &["pixels farther from the model's point distribution are ignored (§5.2)"],
        ),
        key(
            "region_margin_px",
            p.region_margin_px,
            &[
                "the image region around the gate's image grows by this",
                "much on each side (for border detection only)",
            ],
        ),
    ]
}

/// The keys of `[tracker]` on the tracking state: failure, loss, search.
fn tracking_keys(p: &TrackerParams) -> Vec<Key> {
    vec![
        key(
            "min_quality",
            p.min_quality,
            &["below: the registration failed (the matching likelihood", "per surfel, ≈1 good)"],
        ),
        key(
            "min_quality_initialise",
            p.min_quality_initialise,
            &["(re-)initialisation accepts a pose only above this"],
        ),
        key(
            "max_free_space",
            p.max_free_space,
            &[
                "also failed when the depth image sees through more than this",
                "fraction of the model surfels facing the camera (the pose puts",
                "the object in front of the background); 1 turns the check off",
            ],
        ),
        key(
            "free_space_margin_m",
            p.free_space_margin_m,
            &["... a surfel is seen through when the depth measured at its", "pixel lies more than this beyond it"],
        ),
        key(
            "lost_after_frames",
            p.lost_after_frames,
            &["consecutive failed frames before the status becomes \"lost\""],
        ),
        key(
            "retry_from_last_pose",
            p.retry_from_last_pose,
            &[
                "a frame whose registration from the constant-velocity prediction",
                "fails is registered once more from the last pose (costs about",
                "twice the time on such frames; keeps fast, jerky motion tracked)",
            ],
        ),
        key(
            "search_near_last_pose",
            p.search_near_last_pose,
            &[
                "when lost, look for the object around its last pose first (the",
                "object's search region), then around camera_from_object below",
            ],
        ),
        key(
            "follow_tracked_objects",
            p.follow_tracked_objects,
            &[
                "objects not seen (lost, or held after a bad frame) are taken to stay",
                "put relative to the tracked ones (things on a table): their last",
                "pose follows the camera motion a tracked object measures. Off for",
                "objects that move on their own; one object alone is never affected",
            ],
        ),
    ]
}

/// The keys of `[tracker]` on the registration and its covariance (§4).
fn registration_keys(p: &TrackerParams) -> Vec<Key> {
    let r = &p.registration;
    vec![
        key("lm_max_iterations", r.lm_max_iterations, &["Levenberg–Marquardt iterations at most (§4.2)"]),
        key(
            "newton_iterations",
            r.newton_iterations,
            &["Newton iterations on Eq. (4) after LM; 0: LM only, 5 % less", "work per VGA frame, worse maxima"],
        ),
        key("step_tolerance", r.step_tolerance_m, &["LM has converged when a step is below this many m and rad"]),
        key(
            "coarsest_level",
            r.coarsest_level,
            &["registration uses levels 0 (the model's finest: 1.25 cm", "for teddy) to this one (4: 16x coarser)"],
        ),
        key(
            "confirm_convergence",
            r.confirm_with_fresh_associations,
            &[
                "LM stops only after a pass that searches every match afresh;",
                "false: 8 % less work per VGA frame, ATE median +0.3 mm",
                "(docs/benchmarks.md, \"Trading accuracy for time in the tracker\")",
            ],
        ),
        key(
            "start_from_last_matches",
            r.start_from_last_matches,
            &[
                "each frame's first association pass searches around the last",
                "frame's matches; LM still ends after a pass from scratch. false:",
                "from scratch, as the paper; the teddy 2-5 % slower (QVGA +3 %",
                "instructions, VGA +0.6 %), other trajectories, as accurate",
                "(docs/benchmarks.md, \"Trading accuracy for time in the tracker\")",
            ],
        ),
        key(
            "covariance",
            p.covariance.name(),
            &[
                "the published covariance: \"clustered\" lets neighbouring surfel",
                "associations err together (cluster-robust sandwich); \"eq6\" is",
                "Eq. (6) of the paper, which treats each as independent. On",
                "fr3_teddy the errors from frame to frame are 2.8x the clustered",
                "standard deviation and 8.9x Eq. (6)'s (docs/evaluation.md)",
            ],
        ),
        key(
            "covariance_scale",
            p.covariance_scale,
            &[
                "multiplies the published covariance: for fusion in a filter,",
                "9 (3x) matches the frame-to-frame spread of the clustered one;",
                "`mrsmap track --dataset` measures it on a sequence with",
                "ground truth",
            ],
        ),
    ]
}

/// The whole configuration with every key at its default and a comment on each; the
/// objects' keys have no default, and the text holds one example object.
pub fn default_tracker_config() -> String {
    let mut out = String::new();
    comment_lines(&mut out, HEADER);
    for (header, intro, keys) in sections() {
        out.push('\n');
        comment_lines(&mut out, intro);
        let _ = writeln!(out, "{header}");
        for k in &keys {
            write_key(&mut out, k);
        }
    }
    out
}

fn comment_lines(out: &mut String, lines: &[&str]) {
    for line in lines {
        let _ = writeln!(out, "# {line}");
    }
}

/// `name = value` with its comment beside it where the two fit before the comment
/// column and the comment's lines are short, else with the comment above it.
fn write_key(out: &mut String, k: &Key) {
    let assignment = format!("{}{} = {}", if k.commented_out { "# " } else { "" }, k.name, k.value);
    let short = k.comment.iter().all(|line| line.chars().count() <= BESIDE_MAX_CHARS);
    if short && assignment.chars().count() < COMMENT_COLUMN {
        let pad = " ".repeat(COMMENT_COLUMN - assignment.chars().count());
        for (i, line) in k.comment.iter().enumerate() {
            if i == 0 {
                let _ = writeln!(out, "{assignment}{pad}# {line}");
            } else {
                let _ = writeln!(out, "{}# {line}", " ".repeat(COMMENT_COLUMN));
            }
        }
    } else {
        comment_lines(out, k.comment);
        let _ = writeln!(out, "{assignment}");
    }
}

#[cfg(test)]
mod tests {
    use super::super::parse_tracker_config;
    use super::*;
    use std::path::Path;

    /// The keys serde accepts in the table `header`, read from its refusal of an unknown
    /// key (`unknown field …, expected one of …`): every field of the raw struct.
    fn accepted_keys(header: &str) -> Vec<String> {
        let text = format!("{header}\n__probe = 1\n");
        let message = parse_tracker_config(&text, Path::new("t.toml")).unwrap_err().to_string();
        let expected = message.split("expected").nth(1).unwrap_or_else(|| panic!("{header}: {message}"));
        expected.split('`').skip(1).step_by(2).map(str::to_owned).collect()
    }

    #[test]
    fn every_key_the_parser_accepts_is_in_the_template() {
        for (header, _, keys) in sections() {
            let mut written: Vec<String> = keys.iter().map(|k| k.name.to_owned()).collect();
            let mut accepted = accepted_keys(header);
            assert!(!accepted.is_empty(), "{header}");
            written.sort();
            accepted.sort();
            assert_eq!(written, accepted, "{header}");
        }
    }

    #[test]
    fn the_template_parses_to_the_defaults() {
        let p = Path::new("robot_config/tracker.toml");
        let template = parse_tracker_config(&default_tracker_config(), p).expect("the template parses");
        let object = format!(
            "[[object]]\nname = \"teddy\"\nmodel = \"../models/teddy.mrsm\"\ncamera_from_object = {}\nsearch_translation_m = 0.05\nsearch_yaw_deg = 20.0\ncolor_term = false\n",
            TEDDY_CAMERA_FROM_OBJECT.toml()
        );
        let minimal = parse_tracker_config(&object, p).expect("the minimal file parses");
        assert_eq!(template, minimal);
        assert_eq!(template.params, TrackerParams::default());
    }

    #[test]
    fn every_value_line_has_its_comment() {
        let text = default_tracker_config();
        for line in text.lines().filter(|l| l.contains(" = ") && !l.starts_with('#')) {
            let (assignment, comment) = line.split_once('#').unwrap_or((line, ""));
            let above = text.lines().take_while(|l| *l != line).last().unwrap_or("");
            assert!(!comment.trim().is_empty() || above.starts_with("# "), "{assignment}");
        }
    }

    #[test]
    fn the_shipped_tracker_toml_is_the_template() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("robot_config/tracker.toml");
        let shipped = std::fs::read_to_string(&path).expect("robot_config/tracker.toml");
        assert!(
            shipped == default_tracker_config(),
            "robot_config/tracker.toml differs from the defaults in the code: regenerate it with \
             `cargo run --release -- track --print-default-config > robot_config/tracker.toml`"
        );
    }
}
