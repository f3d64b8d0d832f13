//! Inputs that once crashed a fuzz target (fuzz/regressions/TARGET/, see docs/fuzzing.md),
//! replayed on the stable toolchain: each gives an error or a result, never a panic or
//! an abort.

mod common;

use common::{reseal, root};
use mrsmap::io::recording::{RecordingReader, RecordingTopics};
use std::path::PathBuf;

fn regressions(target: &str) -> Vec<PathBuf> {
    let dir = root().join("fuzz/regressions").join(target);
    let mut files: Vec<PathBuf> =
        std::fs::read_dir(&dir).map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect()).unwrap_or_default();
    files.sort();
    assert!(!files.is_empty(), "no regression inputs in {}", dir.display());
    files
}

#[test]
fn model_files_that_crashed_give_errors() {
    for path in regressions("model_file") {
        let bytes = std::fs::read(&path).expect("readable");
        // As the fuzz target does: decoded as found, then with the checksum recomputed.
        let _ = mrsmap::model::decode(&bytes, &path);
        let mut sealed = bytes.clone();
        reseal(&mut sealed);
        let result = mrsmap::model::decode(&sealed, &path);
        let e = result.expect_err("a regression input is damaged");
        eprintln!("{}: {e}", path.display());
    }
}

#[test]
fn recordings_that_crashed_end_in_errors() {
    for path in regressions("mcap_recording") {
        let mut reader = RecordingReader::open(&path, RecordingTopics::default(), None).expect("starts like MCAP");
        let mut frames = 0;
        while let Ok(Some(_)) = reader.next_frame() {
            frames += 1;
            assert!(frames < 64, "{}: endless", path.display());
        }
        assert!(reader.damage().is_some() || frames == 0, "{}", path.display());
    }
}
