//! The pose client's trajectories, written as the poses arrive. Each object's lines go
//! to `<file>.partial` after every wake-up of the client, and the file takes its name
//! when the client stops. A client that is killed leaves the `.partial` file with every
//! pose it had received, and memory does not grow with the length of a run. A write
//! that fails (a full disk) keeps the lines in memory and is tried again at the next
//! wake-up; at the end, what still cannot be written goes to the system's temporary
//! folder, as the other outputs' rescue does. A device or pipe (`--out /dev/stdout`) is
//! written to as it is.

use super::poses_client::object_trajectory_path;
use super::report::{both_written, log_line, rescue};
use crate::io::atomic::{Destination, destination, partial_path};
use anyhow::{Context as _, Result, anyhow};
use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Every object's trajectory file, opened at the object's first pose.
pub struct PoseFiles {
    /// `--out`: the one object's file, or the name the objects' names are inserted into.
    out: PathBuf,
    files: BTreeMap<String, PoseFile>,
}

/// One object's trajectory.
struct PoseFile {
    /// The file it is named (through links), or the device it is written to.
    path: PathBuf,
    /// Where it is written until the end; `None` for a device or pipe.
    partial: Option<PathBuf>,
    /// `None` until it could be opened.
    file: Option<std::fs::File>,
    /// Lines not yet written.
    pending: String,
    /// The last write's failure, if it failed; said once until a write succeeds.
    error: Option<std::io::Error>,
}

impl PoseFiles {
    /// Trajectories named after `out`. Unless `force`, refuses to start where a client
    /// that was killed left `.partial` trajectories: they hold that run's poses.
    pub fn new(out: &Path, force: bool) -> Result<Self> {
        let left = leftover_partials(out);
        if let (Some(first), false) = (left.first(), force) {
            return Err(anyhow!(
                "{} exists: the poses of a client that was stopped before it finished its trajectory \
                 (a valid TUM trajectory up to its last line){}; move it away, or pass --force to replace it",
                first.display(),
                if left.len() > 1 { format!(", and {} more such file(s)", left.len() - 1) } else { String::new() }
            ));
        }
        Ok(PoseFiles { out: out.to_path_buf(), files: BTreeMap::new() })
    }

    /// Adds `line` (with its newline) to object `name`'s trajectory; `objects` is how
    /// many objects the tracker tracks (one: `out` itself, else `out` suffixed by the name).
    pub fn push(&mut self, name: &str, objects: usize, line: &str) {
        if !self.files.contains_key(name) {
            let path = object_trajectory_path(&self.out, name, objects);
            self.files.insert(name.to_string(), PoseFile::new(path, name));
        }
        if let Some(f) = self.files.get_mut(name) {
            f.pending.push_str(line);
        }
    }

    /// Writes the lines received since the last call.
    pub fn write(&mut self) {
        for f in self.files.values_mut() {
            f.write_pending();
        }
    }

    /// Writes what is left and gives each file its name. Every file is tried, whatever
    /// became of the others.
    pub fn finish(self) -> Result<()> {
        let mut written = Ok(());
        for f in self.files.into_values() {
            written = both_written(written, f.finish());
        }
        written
    }
}

impl PoseFile {
    fn new(path: PathBuf, name: &str) -> Self {
        let (path, partial) = match destination(&path) {
            Ok(Destination::Stream) => (path, None),
            Ok(Destination::File(file)) => {
                let partial = partial_path(&file);
                (file, Some(partial))
            }
            // Said when the file is written to.
            Err(_) => {
                let partial = partial_path(&path);
                (path, Some(partial))
            }
        };
        let pending = format!(
            "# mrsmap poses: object_from_camera of '{name}' (the camera in the object frame), stamped with the frames' depth timestamps\n# timestamp tx ty tz qx qy qz qw\n"
        );
        PoseFile { path, partial, file: None, pending, error: None }
    }

    /// Writes the pending lines; on failure keeps what was not written for the next try.
    fn write_pending(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        match self.try_write() {
            Ok(()) => {
                if self.error.take().is_some() {
                    log_line(format_args!("poses: {} is written again", self.path.display()));
                }
            }
            Err(e) => {
                if self.error.is_none() {
                    log_line(format_args!(
                        "poses: cannot write {}: {e}; its poses are kept in memory and written when it can be",
                        self.written_to().display()
                    ));
                }
                self.error = Some(e);
            }
        }
    }

    fn try_write(&mut self) -> std::io::Result<()> {
        let file = match &mut self.file {
            Some(file) => file,
            None => {
                let opened = match &self.partial {
                    Some(partial) => std::fs::File::create(partial)?,
                    None => std::fs::OpenOptions::new().write(true).open(&self.path)?,
                };
                self.file.insert(opened)
            }
        };
        while !self.pending.is_empty() {
            match file.write(self.pending.as_bytes()) {
                Ok(0) => return Err(std::io::ErrorKind::WriteZero.into()),
                // Whole lines or not: a write stops at a byte count, which is kept exactly.
                Ok(n) => drop(self.pending.drain(..n)),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// The file the lines go to now.
    fn written_to(&self) -> &Path {
        self.partial.as_deref().unwrap_or(&self.path)
    }

    fn finish(mut self) -> Result<()> {
        self.write_pending();
        let Some(error) = self.error.take() else {
            return match &self.partial {
                Some(partial) => std::fs::rename(partial, &self.path)
                    .with_context(|| format!("renaming {} to {}", partial.display(), self.path.display())),
                None => Ok(()),
            };
        };
        // The whole trajectory (what the partial file holds, then the rest) to the
        // temporary folder, so that none of its poses is lost.
        // (Only a regular file is read back: a device would read without end.)
        let regular = |p: &&PathBuf| std::fs::metadata(p).is_ok_and(|m| m.is_file());
        let mut whole = self.partial.as_ref().filter(regular).and_then(|p| std::fs::read(p).ok()).unwrap_or_default();
        whole.extend_from_slice(self.pending.as_bytes());
        let error = anyhow::Error::new(error).context(format!("writing {}", self.written_to().display()));
        Err(rescue(&self.path, error, |p| Ok(std::fs::write(p, &whole)?)))
    }
}

/// The `.partial` trajectories a client with `--out out` leaves: `out.partial`, and
/// `<stem>.<object>.<ext>.partial` beside it.
fn leftover_partials(out: &Path) -> Vec<PathBuf> {
    let out = match destination(out) {
        Ok(Destination::File(file)) => file,
        _ => return Vec::new(),
    };
    let (Some(name), Some(stem)) = (out.file_name(), out.file_stem()) else { return Vec::new() };
    let (name, stem) = (name.to_string_lossy(), stem.to_string_lossy());
    let suffix = match out.extension() {
        Some(ext) => format!(".{}.partial", ext.to_string_lossy()),
        None => ".partial".to_string(),
    };
    let Ok(entries) = std::fs::read_dir(super::outputs::folder_of(&out)) else { return Vec::new() };
    let mut left: Vec<PathBuf> = entries
        .filter_map(|e| e.ok())
        .filter(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            n == format!("{name}.partial")
                || (n.starts_with(&format!("{stem}."))
                    && n.ends_with(&suffix)
                    && n.len() > stem.len() + suffix.len() + 1)
        })
        .map(|e| e.path())
        .collect();
    left.sort();
    left
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::scratch_dir;

    #[test]
    fn lines_are_on_disk_after_each_write_and_the_file_takes_its_name_at_the_end() {
        let dir = scratch_dir("pose-files-stream");
        let out = dir.join("traj.txt");
        let mut files = PoseFiles::new(&out, false).expect("nothing left over");
        files.push("teddy", 2, "1.0 0 0 0 0 0 0 1\n");
        files.push("cup", 2, "1.0 1 0 0 0 0 0 1\n");
        files.write();
        let partial = dir.join("traj.teddy.txt.partial");
        let text = std::fs::read_to_string(&partial).expect("written as it comes");
        assert!(
            text.starts_with("# mrsmap poses: object_from_camera of 'teddy'") && text.ends_with("1.0 0 0 0 0 0 0 1\n")
        );
        // What a killed client leaves is refused by the next one, unless forced.
        let err = PoseFiles::new(&out, false).err().expect("refused").to_string();
        assert!(err.contains("traj.cup.txt.partial") && err.contains("1 more") && err.contains("--force"), "{err}");
        assert!(PoseFiles::new(&out, true).is_ok());
        files.push("teddy", 2, "2.0 0 0 0 0 0 0 1\n");
        files.finish().expect("finished");
        assert!(!partial.exists());
        let text = std::fs::read_to_string(dir.join("traj.teddy.txt")).expect("named");
        assert_eq!(text.lines().filter(|l| !l.starts_with('#')).count(), 2);
        assert!(std::fs::read_to_string(dir.join("traj.cup.txt")).expect("named").contains("1.0 1 0"));
        assert!(leftover_partials(&out).is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn lines_that_cannot_be_written_are_kept_and_rescued_whole() {
        let dir = scratch_dir("pose-files-full");
        let out = dir.join("traj.txt");
        // The partial file is a link to /dev/full: every write fails with ENOSPC.
        std::os::unix::fs::symlink("/dev/full", dir.join("traj.txt.partial")).expect("symlink");
        let mut files = PoseFiles::new(&out, true).expect("forced");
        files.push("teddy", 1, "1.0 0 0 0 0 0 0 1\n");
        files.write();
        files.push("teddy", 1, "2.0 0 0 0 0 0 0 1\n");
        let err = files.finish().expect_err("the disk is full");
        let text = format!("{err:#}");
        let rescue = crate::app::report::rescue_path(&out);
        assert!(text.contains("No space left on device") && text.contains(&rescue.display().to_string()), "{text}");
        let rescued = std::fs::read_to_string(&rescue).expect("rescued");
        assert!(rescued.starts_with("# mrsmap poses") && rescued.ends_with("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1\n"));
        let _ = std::fs::remove_file(&rescue);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
