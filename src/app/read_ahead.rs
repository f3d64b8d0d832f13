//! Reading a recording one frame ahead on its own thread, so that decompression and
//! decoding overlap the tracker step. Frames arrive in file order (the output does not
//! depend on the timing); their buffers are handed back and reused.

use crate::frame::OwnedFrame;
use crate::io::frames::halve;
use crate::io::recording::{RecordingError, RecordingReader};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

/// Frames read ahead by a separate thread.
pub struct ReadAhead {
    frames: Option<Receiver<Result<OwnedFrame, RecordingError>>>,
    recycle: SyncSender<OwnedFrame>,
    thread: Option<JoinHandle<RecordingReader>>,
}

impl std::fmt::Debug for ReadAhead {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReadAhead").finish_non_exhaustive()
    }
}

/// Frames decoded but not yet taken.
const AHEAD: usize = 2;

impl ReadAhead {
    /// Starts reading `reader` on a new thread; with `half`, frames are subsampled by two
    /// (QVGA from VGA), as `--qvga` does for datasets.
    pub fn start(mut reader: RecordingReader, half: bool) -> std::io::Result<Self> {
        let (tx, frames) = sync_channel(AHEAD);
        let (recycle, recycled) = sync_channel::<OwnedFrame>(AHEAD + 2);
        let thread = std::thread::Builder::new().name("mrsmap-read-ahead".into()).spawn(move || {
            loop {
                let mut owned = recycled.try_recv().unwrap_or_default();
                let read = if half {
                    reader.next_frame().map(|f| {
                        f.map(|f| {
                            owned.stamp_ns = f.stamp_ns;
                            owned.camera = halve(&f, &mut owned.rgb, &mut owned.depth).ok().map(|h| h.camera);
                        })
                        .is_some()
                    })
                } else {
                    // The frame's buffers change hands (no copy of the images).
                    reader.next_frame_into(&mut owned)
                };
                let next = match read {
                    Ok(true) => Ok(owned),
                    Ok(false) => break,
                    Err(e) => Err(e),
                };
                let stop = next.is_err();
                if tx.send(next).is_err() || stop {
                    break;
                }
            }
            reader
        })?;
        Ok(ReadAhead { frames: Some(frames), recycle, thread: Some(thread) })
    }

    /// The next frame; `None` at the end (or damage: see the reader after [`Self::finish`]).
    pub fn next_frame(&mut self) -> Option<Result<OwnedFrame, RecordingError>> {
        self.frames.as_ref()?.recv().ok()
    }

    /// Hands a frame's buffers back for reuse.
    pub fn give_back(&self, frame: OwnedFrame) {
        let _ = self.recycle.try_send(frame);
    }

    /// Stops reading and returns the reader (its statistics and damage).
    pub fn finish(mut self) -> Option<RecordingReader> {
        self.frames = None;
        self.thread.take().and_then(|t| t.join().ok())
    }
}
