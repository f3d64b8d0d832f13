//! Helpers shared by the library's unit tests.

use std::path::PathBuf;

/// A fresh, empty folder `mrsmap-<tag>-<pid>` in the system's temporary folder (an
/// earlier run's is removed first).
pub(crate) fn scratch_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mrsmap-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a scratch folder");
    dir
}
