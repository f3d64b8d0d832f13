//! Writing a file whole or not at all.

use std::path::{Path, PathBuf};

/// The temporary name [`write_whole`] writes to: `path` with `.partial` appended.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".partial");
    PathBuf::from(name)
}

/// Writes `bytes` to `path` through a temporary file beside it, renamed into place when
/// complete: a full disk or a crash never leaves a truncated file that reads as a
/// shorter valid one (a trajectory missing its last poses), nor replaces a good file.
/// On failure the temporary file is removed, so that it does not hold the space the
/// write lacked.
pub fn write_whole(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = partial_path(path);
    let result = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_whole_file_replaces_the_old_one_and_leaves_no_partial_file() {
        let dir = std::env::temp_dir().join(format!("mrsmap-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("traj.txt");
        std::fs::write(&path, b"old").expect("writes");
        write_whole(&path, b"new contents").expect("writes whole");
        assert_eq!(std::fs::read(&path).expect("reads"), b"new contents");
        assert!(!partial_path(&path).exists());
        // A failed write (here: into a folder that does not exist) leaves nothing behind.
        let missing = dir.join("no/such/folder/traj.txt");
        assert!(write_whole(&missing, b"x").is_err());
        assert!(!partial_path(&missing).exists() && !missing.exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
