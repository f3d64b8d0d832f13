//! Reading a recording one frame ahead, beside the tracker step on the same workers: the
//! replay reads and decodes frame `n + 1` in a `rayon::join` with the step of frame `n`,
//! so decompression takes the cores' spare time within the step (its serial stretches
//! and the end of its parallel loops) instead of a third thread preempting the step's
//! two workers. Frames arrive in file order, and the output does not depend on the
//! timing. Two frames' buffers (the one tracked and the one read) are reused throughout.

use crate::frame::OwnedFrame;
use crate::io::frames::halve;
use crate::io::recording::{RecordingError, RecordingReader};

/// Reads the next frame of `reader` into `owned`'s buffers (halved with `half`: QVGA from
/// VGA, as `--qvga` does for datasets); `Ok(None)` at the end of the recording or at its
/// damage (the reader keeps what it found). A panic while reading (a bug) becomes an
/// error, so that the replay still writes the poses tracked before it.
pub fn read_frame(reader: &mut RecordingReader, half: bool, owned: OwnedFrame) -> anyhow::Result<Option<OwnedFrame>> {
    let read = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read_into(reader, half, owned)));
    read.map_err(|_| anyhow::anyhow!("reading the recording failed (a bug in the reader; it panicked)"))?
        .map_err(anyhow::Error::from)
}

fn read_into(
    reader: &mut RecordingReader,
    half: bool,
    mut owned: OwnedFrame,
) -> Result<Option<OwnedFrame>, RecordingError> {
    let read = if half {
        reader
            .next_frame()?
            .map(|f| {
                owned.stamp_ns = f.stamp_ns;
                owned.camera = halve(&f, &mut owned.rgb, &mut owned.depth).ok().map(|h| h.camera);
            })
            .is_some()
    } else {
        // The frame's buffers change hands (no copy of the images).
        reader.next_frame_into(&mut owned)?
    };
    Ok(read.then_some(owned))
}
