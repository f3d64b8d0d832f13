//! A zstd decompressor for the indexed MCAP reader that decodes a whole chunk in one call,
//! straight into its destination.
//!
//! The `mcap` crate's built-in zstd decoder streams: zstd decodes into its own window and
//! copies the bytes out, the size of the chunk again (~1.5 MB per VGA frame pair). The
//! indexed reader hands a decompressor the whole compressed chunk and a destination of the
//! chunk's full uncompressed size, which is what zstd's one-shot decoding needs. Whatever
//! it cannot decode at once (a destination too small, bytes after the last frame) is
//! decoded by streaming, exactly as the built-in decoder does: the bytes delivered, and
//! the errors, are the same.

use mcap::sans_io::decompressor::{DecompressResult, Decompressor};
use mcap::{McapError, McapResult};
use zstd::zstd_safe::{DCtx, InBuffer, OutBuffer, ResetDirective, get_error_name};

/// See the module documentation.
#[derive(Default)]
pub(crate) struct WholeChunkZstd {
    /// The decoding context, created on first use and kept across chunks.
    context: Option<DCtx<'static>>,
    /// This chunk is being streamed (the one-shot decoding did not apply).
    streaming: bool,
    /// This chunk was decoded whole: nothing more comes out of it.
    done: bool,
    /// The input the stream asks for next (0: any).
    need: usize,
}

fn error(code: usize) -> McapError {
    McapError::DecompressionError(get_error_name(code).into())
}

impl WholeChunkZstd {
    fn context(&mut self) -> &mut DCtx<'static> {
        self.context.get_or_insert_with(DCtx::create)
    }

    /// One streaming step, as the built-in decoder takes it.
    fn stream(&mut self, src: &[u8], dst: &mut [u8]) -> McapResult<DecompressResult> {
        let mut input = InBuffer::around(src);
        let mut output = OutBuffer::around(dst);
        self.need = self.context().decompress_stream(&mut output, &mut input).map_err(error)?;
        Ok(DecompressResult { consumed: input.pos, wrote: output.pos() })
    }
}

impl Decompressor for WholeChunkZstd {
    fn next_read_size(&self) -> usize {
        self.need
    }

    fn decompress(&mut self, src: &[u8], dst: &mut [u8]) -> McapResult<DecompressResult> {
        if self.done {
            return Ok(DecompressResult { consumed: 0, wrote: 0 });
        }
        if !self.streaming {
            // The first call for this chunk: try it whole. Any failure starts over by
            // streaming (one-shot decoding keeps no state), which then decides.
            if let Ok(wrote) = self.context().decompress(dst, src) {
                self.done = true;
                return Ok(DecompressResult { consumed: src.len(), wrote });
            }
            self.streaming = true;
            self.context().reset(ResetDirective::SessionOnly).map_err(error)?;
        }
        self.stream(src, dst)
    }

    fn reset(&mut self) -> McapResult<()> {
        self.streaming = false;
        self.done = false;
        self.need = 0;
        if let Some(context) = self.context.as_mut() {
            context.reset(ResetDirective::SessionOnly).map_err(error)?;
        }
        Ok(())
    }

    fn name(&self) -> &'static str {
        "zstd"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(data: &[u8]) -> Vec<u8> {
        zstd::bulk::compress(data, 3).expect("compress")
    }

    /// Runs the indexed reader's loop (`mcap`'s `decompress_chunk`): calls until the
    /// declared size is written, failing on a call that makes no progress.
    fn decode(d: &mut WholeChunkZstd, src: &[u8], size: usize, step: usize) -> McapResult<Vec<u8>> {
        let mut dst = vec![0u8; size];
        let (mut i, mut o) = (0, 0);
        while o < size {
            let end = o.saturating_add(step).min(size);
            let r = d.decompress(&src[i..], &mut dst[o..end])?;
            if r.consumed == 0 && r.wrote == 0 {
                return Err(McapError::DecompressionError("no progress".into()));
            }
            (i, o) = (i + r.consumed, o + r.wrote);
        }
        d.reset()?;
        Ok(dst)
    }

    #[test]
    fn decodes_whole_chunks_and_falls_back_to_streaming() {
        let data: Vec<u8> = (0..200_000u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8 % 7).collect();
        let mut d = WholeChunkZstd::default();
        // Whole, in one call; twice, through the reset.
        for _ in 0..2 {
            assert_eq!(decode(&mut d, &frame(&data), data.len(), usize::MAX).expect("whole"), data);
        }
        // Two frames in one chunk.
        let two = [frame(&data[..70_000]), frame(&data[70_000..])].concat();
        assert_eq!(decode(&mut d, &two, data.len(), usize::MAX).expect("two frames"), data);
        // A destination of 4 kB at a time: one-shot cannot, streaming does.
        assert_eq!(decode(&mut d, &frame(&data), data.len(), 4096).expect("small steps"), data);
        // Bytes after the last frame are left unread, as the built-in decoder leaves them.
        let trailing = [frame(&data), vec![0xAB; 16]].concat();
        assert_eq!(decode(&mut d, &trailing, data.len(), usize::MAX).expect("trailing"), data);
        // Damage is an error, and the next chunk decodes again.
        let mut bad = frame(&data);
        let mid = bad.len() / 2;
        bad[mid..mid + 64].fill(0x5A);
        assert!(decode(&mut d, &bad, data.len(), usize::MAX).is_err());
        d.reset().expect("reset");
        assert_eq!(decode(&mut d, &frame(&data), data.len(), usize::MAX).expect("after damage"), data);
        // A declared size larger than the data: no progress, an error (not a hang).
        assert!(decode(&mut d, &frame(&data), data.len() + 10, usize::MAX).is_err());
    }
}
