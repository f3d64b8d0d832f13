//! MCAP recordings: whatever the file holds, opening it and reading its frames ends in
//! frames, the end, or a typed error (naming topic and message), never a panic; reading
//! stops after a bounded number of steps (no endless loop on a damaged index).
//!
//! The reader takes a path, so each input is written to a file in the temporary
//! directory first (one per fuzzing process).

#![no_main]

use libfuzzer_sys::fuzz_target;
use mrsmap::io::recording::{RecordingReader, RecordingTopics};
use std::path::PathBuf;
use std::sync::OnceLock;

/// Frames read at most per input: the seeds hold fewer.
const MAX_FRAMES: usize = 64;

fn path() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| std::env::temp_dir().join(format!("mrsmap-fuzz-{}.mcap", std::process::id())))
}

/// The topic sets of the fixtures in tests/data: raw and compressed ROS 2 images.
fn topic_sets() -> [RecordingTopics; 2] {
    let raw = RecordingTopics::default();
    let compressed = RecordingTopics {
        color: format!("{}/compressed", raw.color),
        depth: format!("{}/compressedDepth", raw.depth),
        camera_info: raw.camera_info.clone(),
    };
    [raw, compressed]
}

fuzz_target!(|data: &[u8]| {
    if std::fs::write(path(), data).is_err() {
        return;
    }
    for topics in topic_sets() {
        let Ok(mut reader) = RecordingReader::open(path(), topics, None) else { return };
        for _ in 0..MAX_FRAMES {
            match reader.next_frame() {
                Ok(Some(frame)) => {
                    let pixels = frame.width() * frame.height();
                    assert_eq!((frame.rgb.len(), frame.depth.len()), (3 * pixels, pixels));
                }
                Ok(None) | Err(_) => break,
            }
        }
        let _ = (reader.stats(), reader.damage(), reader.skipped_chunks());
    }
});
