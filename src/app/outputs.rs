//! Checks of a command's output paths before it runs: each can be written, none is a
//! file the run reads, and no two are the same file. A mistyped path must not cost the
//! user a recording, a model, a dataset's ground truth, or the run's own results.

use crate::io::tracker_config::TrackerConfig;
use std::path::{Path, PathBuf};

/// A file a command reads: what it is (for messages, e.g. "the dataset's
/// groundtruth.txt") and its path.
pub type Input = (String, PathBuf);

/// The index files of a TUM dataset folder that exist (`rgb.txt`, `depth.txt`,
/// `associations.txt`, `groundtruth.txt`): the files a run over it reads besides the
/// images.
pub fn dataset_inputs(dir: &Path) -> Vec<Input> {
    ["rgb.txt", "depth.txt", "associations.txt", "groundtruth.txt"]
        .into_iter()
        .map(|name| (format!("the dataset's {name}"), dir.join(name)))
        .filter(|(_, path)| path.exists())
        .collect()
}

/// The files a tracker configuration brings in: the configuration itself and each
/// object's model.
pub fn tracker_inputs(config_path: &Path, config: &TrackerConfig) -> Vec<Input> {
    let mut inputs = vec![named("the tracker configuration", config_path)];
    inputs.extend(config.objects.iter().map(|o| named(&format!("the model of '{}'", o.name), &o.model)));
    inputs
}

/// [`dataset_inputs`] with the camera file.
pub fn dataset_and_camera(dataset: &Path, camera: Option<&Path>) -> Vec<Input> {
    let mut inputs = dataset_inputs(dataset);
    inputs.extend(camera.map(|c| named("the camera file", c)));
    inputs
}

/// `(description, path)` of one file, for the lists of inputs.
pub fn named(what: &str, path: &Path) -> Input {
    (what.to_string(), path.to_path_buf())
}

/// Checks, before a run, each output given on the command line (`flag`, its path):
/// it is none of `inputs` (the run would destroy what it reads), no other output names
/// the same file (one would overwrite the other), and it can be written
/// ([`check_writable`]). Symbolic and hard links count as the same file.
pub fn check_outputs<'a>(
    outputs: impl IntoIterator<Item = (&'a str, Option<&'a Path>)>,
    inputs: &[Input],
) -> anyhow::Result<()> {
    let outputs: Vec<(&str, &Path)> = outputs.into_iter().filter_map(|(flag, p)| p.map(|p| (flag, p))).collect();
    for (k, &(flag, path)) in outputs.iter().enumerate() {
        if let Some((what, _)) = inputs.iter().find(|(_, input)| same_file(path, input)) {
            anyhow::bail!(
                "{flag} {} is {what}, which this run reads: writing there would destroy it; choose another path",
                path.display()
            );
        }
        if let Some(&(other, _)) = outputs[..k].iter().find(|&&(_, earlier)| same_file(path, earlier)) {
            anyhow::bail!("{other} and {flag} name the same file ({}): one would overwrite the other", path.display());
        }
        check_writable(path).map_err(|e| anyhow::anyhow!("{flag} {}: cannot write there: {e}", path.display()))?;
    }
    Ok(())
}

/// Refuses to replace `path` if it exists and `force` is not given: "PATH exists; pass
/// --force to replace it", followed by ` (note)` when there is one.
pub fn refuse_to_replace(path: &Path, force: bool, note: Option<&str>) -> anyhow::Result<()> {
    if path.exists() && !force {
        let note = note.map(|n| format!(" ({n})")).unwrap_or_default();
        anyhow::bail!("{} exists; pass --force to replace it{note}", path.display());
    }
    Ok(())
}

/// Checks, before a long run, that a file can be written at `path` (once the run ends):
/// `path` is not a folder, the folder of the file it names (through links) exists, and
/// a file can be created there (one is created and removed). A run's results are then
/// not lost at its end to a mistyped folder or a missing permission. A device or pipe
/// (`/dev/stdout`) is written to as it is: nothing is created beside it.
pub fn check_writable(path: &Path) -> std::io::Result<()> {
    use crate::io::atomic::{Destination, destination};
    use std::io::{Error, ErrorKind};
    let file = match destination(path)? {
        Destination::File(file) => file,
        Destination::Stream => return Ok(()),
    };
    let folder = folder_of(&file);
    if !folder.is_dir() {
        return Err(Error::new(ErrorKind::NotFound, format!("folder {} does not exist", folder.display())));
    }
    let probe = folder.join(format!(".mrsmap-write-check-{}", std::process::id()));
    std::fs::File::create(&probe)?;
    std::fs::remove_file(&probe)
}

/// The folder `path` is in (`.` for a bare name).
pub(super) fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Whether `a` and `b` name the same file: for two files that exist, the same file on
/// disk (through any links); otherwise the same resolved path (the folder resolved, then
/// the name), which is how two outputs not yet written can collide.
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(ma), Ok(mb)) => same_on_disk(&ma, &mb, a, b),
        _ => matches!((resolved(a), resolved(b)), (Some(x), Some(y)) if x == y),
    }
}

#[cfg(unix)]
fn same_on_disk(ma: &std::fs::Metadata, mb: &std::fs::Metadata, _: &Path, _: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    ma.dev() == mb.dev() && ma.ino() == mb.ino()
}

#[cfg(not(unix))]
fn same_on_disk(_: &std::fs::Metadata, _: &std::fs::Metadata, a: &Path, b: &Path) -> bool {
    matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y)
}

/// `path` with its links resolved: the file itself if it exists, else its resolved
/// folder joined with its name; `None` if the folder does not resolve either.
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = path.canonicalize() {
        return Some(p);
    }
    Some(folder_of(path).canonicalize().ok()?.join(path.file_name()?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::scratch_dir;

    #[test]
    fn an_output_that_is_an_input_is_refused_through_any_link() {
        let dir = scratch_dir("outputs-input");
        let gt = dir.join("groundtruth.txt");
        std::fs::write(&gt, "1 0 0 0 0 0 0 1\n").expect("writes");
        std::fs::create_dir(dir.join("sub")).expect("a folder");
        let inputs = vec![named("the dataset's groundtruth.txt", &gt)];
        let refused = |path: &Path| check_outputs([("--out", Some(path))], &inputs).expect_err("refused").to_string();
        let err = refused(&gt);
        assert!(
            err.contains("--out") && err.contains("is the dataset's groundtruth.txt, which this run reads"),
            "{err}"
        );
        // The same file by another spelling, a symbolic link and a hard link.
        assert!(refused(&dir.join("sub/../groundtruth.txt")).contains("which this run reads"));
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&gt, dir.join("link.txt")).expect("a symbolic link");
            assert!(refused(&dir.join("link.txt")).contains("which this run reads"));
        }
        std::fs::hard_link(&gt, dir.join("hard.txt")).expect("a hard link");
        assert!(refused(&dir.join("hard.txt")).contains("which this run reads"));
        // Another file, existing or not, is fine; so is no output.
        std::fs::write(dir.join("traj.txt"), "").expect("writes");
        check_outputs([("--out", Some(dir.join("traj.txt").as_path()))], &inputs).expect("another file");
        check_outputs([("--out", Some(dir.join("new.txt").as_path()))], &inputs).expect("a new file");
        check_outputs([("--out", None)], &inputs).expect("no output");
        // The input is untouched.
        assert_eq!(std::fs::read_to_string(&gt).expect("reads"), "1 0 0 0 0 0 0 1\n");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn two_outputs_naming_one_file_are_refused_whether_or_not_it_exists() {
        let dir = scratch_dir("outputs-twice");
        let (a, b) = (dir.join("poses.mcap"), dir.join("./poses.mcap"));
        let err = check_outputs([("--out", Some(a.as_path())), ("--trajectory", Some(b.as_path()))], &[])
            .expect_err("the same new file")
            .to_string();
        assert!(err.contains("--out and --trajectory name the same file"), "{err}");
        std::fs::write(&a, "").expect("writes");
        assert!(check_outputs([("--out", Some(a.as_path())), ("--trajectory", Some(b.as_path()))], &[]).is_err());
        let c = dir.join("traj.txt");
        check_outputs([("--out", Some(a.as_path())), ("--trajectory", Some(c.as_path()))], &[]).expect("two files");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn an_existing_file_is_replaced_only_with_force() {
        let dir = scratch_dir("outputs-replace");
        let (old, new) = (dir.join("old.mcap"), dir.join("new.mcap"));
        std::fs::write(&old, "").expect("writes");
        let err = refuse_to_replace(&old, false, None).expect_err("exists").to_string();
        assert_eq!(err, format!("{} exists; pass --force to replace it", old.display()));
        let err = refuse_to_replace(&old, false, Some("why")).expect_err("exists").to_string();
        assert_eq!(err, format!("{} exists; pass --force to replace it (why)", old.display()));
        refuse_to_replace(&old, true, None).expect("forced");
        refuse_to_replace(&new, false, None).expect("a new file");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_dataset_lists_the_index_files_it_has() {
        let dir = scratch_dir("outputs-dataset");
        std::fs::write(dir.join("rgb.txt"), "").expect("writes");
        std::fs::write(dir.join("groundtruth.txt"), "").expect("writes");
        let names: Vec<String> = dataset_inputs(&dir).into_iter().map(|(what, _)| what).collect();
        assert_eq!(names, ["the dataset's rgb.txt", "the dataset's groundtruth.txt"]);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
