//! Writing a file whole or not at all.

use std::io::{Error, ErrorKind};
use std::path::{Path, PathBuf};

/// The temporary name [`write_whole`] writes to: `path` with `.partial` appended.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".partial");
    PathBuf::from(name)
}

/// Where an output named `path` goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Destination {
    /// A regular file, or none yet: the file itself, through any symbolic links (a
    /// rename onto the link would replace the link and leave the file it names stale,
    /// and a temporary file beside the link could lie on another file system).
    File(PathBuf),
    /// An existing device, pipe or socket (`/dev/stdout`, `/dev/null`, a FIFO): written
    /// to as it is. A rename would replace it with a regular file.
    Stream,
}

/// Where an output named `path` goes; an error if it names a folder.
pub fn destination(path: &Path) -> std::io::Result<Destination> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => Err(Error::new(ErrorKind::IsADirectory, "is a folder")),
        Ok(m) if m.is_file() => Ok(Destination::File(path.canonicalize()?)),
        Ok(_) => Ok(Destination::Stream),
        Err(e) if e.kind() == ErrorKind::NotFound => Ok(Destination::File(path.to_path_buf())),
        Err(e) => Err(e),
    }
}

/// The regular file an output that must be a file (an MCAP file, which is written with
/// seeks back to its start) goes to: [`Destination::File`], or an error naming why not.
pub fn file_destination(path: &Path) -> std::io::Result<PathBuf> {
    match destination(path)? {
        Destination::File(file) => Ok(file),
        Destination::Stream => Err(Error::new(
            ErrorKind::InvalidInput,
            "not a regular file (a device, pipe or socket): this output must be a file",
        )),
    }
}

/// Writes `bytes` to `path` through a temporary file beside it, renamed into place when
/// complete: a full disk or a crash never leaves a truncated file that reads as a
/// shorter valid one (a trajectory missing its last poses), nor replaces a good file.
/// On failure the temporary file is removed, so that it does not hold the space the
/// write lacked. A `path` that is a device or pipe ([`Destination::Stream`]) is written
/// to directly.
pub fn write_whole(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let file = match destination(path)? {
        Destination::File(file) => file,
        Destination::Stream => return std::fs::write(path, bytes),
    };
    let tmp = partial_path(&file);
    let result = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, &file));
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
        let dir = crate::test_support::scratch_dir("atomic");
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

    #[cfg(unix)]
    #[test]
    fn a_link_is_written_through_and_a_device_is_written_to_not_replaced() {
        let dir = crate::test_support::scratch_dir("atomic-link");
        std::fs::create_dir_all(dir.join("results")).expect("temp dir");
        let (file, link) = (dir.join("results/run1.txt"), dir.join("traj.txt"));
        std::fs::write(&file, b"old").expect("writes");
        std::os::unix::fs::symlink(&file, &link).expect("a symbolic link");
        write_whole(&link, b"new").expect("writes through the link");
        assert!(std::fs::symlink_metadata(&link).expect("exists").file_type().is_symlink(), "the link stays");
        assert_eq!(std::fs::read(&file).expect("reads"), b"new");
        assert!(!partial_path(&link).exists() && !partial_path(&file).exists());
        // A device stays a device (a rename would have replaced /dev/null with a file).
        let null = Path::new("/dev/null");
        assert_eq!(destination(null).expect("exists"), Destination::Stream);
        write_whole(null, b"to nowhere").expect("writes to the device");
        assert!(!std::fs::metadata(null).expect("exists").is_file());
        let err = file_destination(null).expect_err("not a file").to_string();
        assert!(err.starts_with("not a regular file"), "{err}");
        // A folder is refused, and left as it is.
        let err = write_whole(&dir.join("results"), b"x").expect_err("a folder");
        assert_eq!(err.kind(), ErrorKind::IsADirectory);
        assert!(dir.join("results").is_dir() && !partial_path(&dir.join("results")).exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
