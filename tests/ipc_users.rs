//! iceoryx2 0.10 makes its runtime folders for their creator's user alone: a process of
//! another user (the camera driver run as root once, the tracker as the robot's user)
//! cannot create a node, and iceoryx2 says only `InternalError`. mrsmap's error names the
//! folder, its owner and what to do.
//!
//! The test needs root: it runs in a mount namespace of its own (`unshare -m`) with fresh
//! `/tmp` and `/dev/shm`, so that no other iceoryx2 process sees it, and becomes the user
//! `nobody` with `setpriv`. Where that is not possible it says so and passes, unless
//! `MRSMAP_REQUIRE_NAMESPACES=1` (as `.ci/run` sets).

mod common;

use common::mrsmap_bin;
use std::process::Command;

#[test]
fn a_process_of_another_user_is_told_whose_iceoryx2_folder_it_cannot_use() {
    // Root makes the folders (a pose client that finds no tracker), then `nobody` tries
    // the same. The binary is copied into the private /tmp: the build folder may not be
    // readable by `nobody`, and may itself lie under the /tmp that the mount hides (it is
    // opened first for that).
    let script = r#"
        set -u
        exec 3< "$1" || { echo "SETUP: cannot read $1"; exit 1; }
        mount --make-rprivate / && mount -t tmpfs -o mode=1777 none /tmp && mount -t tmpfs -o mode=1777 none /dev/shm \
            || { echo "SETUP: no private mounts"; exit 0; }
        cat <&3 > /tmp/mrsmap && chmod 755 /tmp/mrsmap
        /tmp/mrsmap poses --service users_test/poses --timeout 1 > /dev/null 2>&1
        echo "root: $?"
        setpriv --reuid=65534 --regid=65534 --clear-groups /tmp/mrsmap poses --service users_test/poses --timeout 1
        echo "nobody: $?"
    "#;
    // `/proc/self` belongs to the process's effective user.
    let is_root = std::fs::metadata("/proc/self").is_ok_and(|m| std::os::unix::fs::MetadataExt::uid(&m) == 0);
    let out = is_root
        .then(|| Command::new("unshare").args(["-m", "sh", "-c", script, "sh"]).arg(mrsmap_bin()).output().ok())
        .flatten();
    let text =
        out.as_ref().map(|o| format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr)));
    let Some(text) = text.filter(|t| t.contains("root: ")) else {
        assert!(
            std::env::var("MRSMAP_REQUIRE_NAMESPACES").as_deref() != Ok("1"),
            "needs root, unshare and setpriv, and MRSMAP_REQUIRE_NAMESPACES=1: {out:?}"
        );
        eprintln!("note: not root, or no mount namespace here: the test of another user's iceoryx2 folder did not run");
        return;
    };
    // The first client failed as it should (no tracker), after making the folders.
    assert!(text.contains("root: 1"), "{text}");
    assert!(text.contains("nobody: 1"), "{text}");
    for needed in [
        "creating node mrsmap_poses",
        "belongs to user 0",
        "this process's user 65534 cannot use it",
        "as one user",
        "/dev/shm/iox2_*",
    ] {
        assert!(text.contains(needed), "missing {needed:?} in: {text}");
    }
}
