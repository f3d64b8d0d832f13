//! Streaming an MCAP file from its start (no usable summary): records cut out of the file
//! here, chunks decompressed whole into one buffer and the records in them read with
//! every length checked against what is left.
//!
//! The `mcap` crate's streaming reader (0.26) walks an uncompressed chunk's records with a
//! subtraction that overflows when a damaged record claims more bytes than the chunk has
//! left (found by fuzzing, `fuzz/regressions/mcap_recording/`): a debug build panics, a
//! release build wraps and reads the bytes after the chunk as if they were in it. Here
//! such a record is "Chunk ended in the middle of a record".
//!
//! A file cut off inside a chunk (a copy that stopped, a full disk) still gives the
//! messages of the chunk's part that is there: what decompresses of it is read up to its
//! last whole record, then the cut is reported.

use super::mcap_source::{MAX_RECORD_BYTES, RawMessage};
use super::zstd_chunk::WholeChunkZstd;
use mcap::read::ChannelAccumulator;
use mcap::records::{Record, op};
use mcap::sans_io::decompressor::Decompressor;
use mcap::{McapError, McapResult};
use std::fs::File;
use std::io::{BufReader, Read};

/// Bytes of a record's opcode and length.
const OPCODE_LEN_SIZE: usize = 9;

/// An MCAP file read from start to end.
pub(super) struct Streamed {
    file: BufReader<File>,
    channels: ChannelAccumulator<'static>,
    topics: Vec<String>,
    /// The body of the file record being read (a whole chunk, compressed).
    record: Vec<u8>,
    /// The records of the chunk being read, decompressed …
    chunk: Vec<u8>,
    /// … where its next record starts …
    at: usize,
    /// … and, for a chunk the file cuts off, the error to report after its whole records.
    cut: Option<McapError>,
    zstd: WholeChunkZstd,
    /// Past the data end record: what follows (the summary) repeats what was read.
    past_data_end: bool,
}

impl Streamed {
    /// Reads `file` (positioned just after the magic) for the messages of `topics`.
    pub(super) fn new(file: File, topics: Vec<String>) -> Self {
        Streamed {
            file: BufReader::with_capacity(1 << 20, file),
            channels: ChannelAccumulator::default(),
            topics,
            record: Vec::new(),
            chunk: Vec::new(),
            at: 0,
            cut: None,
            zstd: WholeChunkZstd::default(),
            past_data_end: false,
        }
    }

    /// The next message of a chosen topic, handed to `visit`; `None` after the footer and
    /// the closing magic, an error where the file is damaged or ends early.
    pub(super) fn next<R>(&mut self, visit: &mut impl FnMut(RawMessage<'_>) -> R) -> Option<McapResult<R>> {
        loop {
            if self.at < self.chunk.len() {
                let rest = &self.chunk[self.at..];
                let whole = rest.get(1..OPCODE_LEN_SIZE).map(|b| {
                    let len = u64::from_le_bytes(b.try_into().unwrap_or_default());
                    (len, len <= (rest.len() - OPCODE_LEN_SIZE) as u64)
                });
                let Some((len, true)) = whole else {
                    if self.cut.is_some() {
                        self.at = self.chunk.len(); // the cut record itself: reported below
                        continue;
                    }
                    return Some(Err(McapError::UnexpectedEoc));
                };
                let (opcode, body) = (rest[0], &rest[OPCODE_LEN_SIZE..OPCODE_LEN_SIZE + len as usize]);
                self.at += OPCODE_LEN_SIZE + len as usize;
                // A chunk cannot hold a data end or a chunk: skipped like any stray record.
                if opcode == op::DATA_END || opcode == op::CHUNK {
                    continue;
                }
                match message_of(&mut self.channels, &self.topics, self.past_data_end, opcode, body, visit) {
                    Some(out) => return Some(out),
                    None => continue,
                }
            }
            if let Some(e) = self.cut.take() {
                return Some(Err(e));
            }
            match self.next_file_record() {
                Err(e) => return Some(Err(e)),
                Ok(None) => return None,
                Ok(Some(op::CHUNK)) => {}
                Ok(Some(opcode)) => {
                    let body = &self.record;
                    match message_of(&mut self.channels, &self.topics, self.past_data_end, opcode, body, visit) {
                        Some(out) => return Some(out),
                        None => continue,
                    }
                }
            }
        }
    }

    /// Reads the next record of the file into `record` (a chunk: into `chunk`, decompressed)
    /// and returns its opcode; `None` after the footer and the closing magic.
    fn next_file_record(&mut self) -> McapResult<Option<u8>> {
        let mut head = [0u8; OPCODE_LEN_SIZE];
        if read_up_to(&mut self.file, &mut head)? < head.len() {
            return Err(McapError::UnexpectedEof);
        }
        let opcode = head[0];
        let len = u64::from_le_bytes(head[1..].try_into().unwrap_or_default());
        let size = usize::try_from(len)
            .ok()
            .filter(|&n| n <= MAX_RECORD_BYTES)
            .ok_or(McapError::RecordTooLarge { opcode, len })?;
        self.record.resize(size, 0);
        let read = read_up_to(&mut self.file, &mut self.record)?;
        if opcode == op::CHUNK {
            self.chunk.clear();
            self.at = 0;
            if read < size {
                // Cut off: what decompresses of the part there is, then the cut (the
                // decompressor's own error, where the data ran out, says no more).
                self.record.truncate(read);
                let _ = decompress_chunk(&self.record, &mut self.chunk, &mut self.zstd, false);
                self.cut = Some(McapError::UnexpectedEof);
                return Ok(Some(op::CHUNK));
            }
            decompress_chunk(&self.record, &mut self.chunk, &mut self.zstd, true)?;
            return Ok(Some(op::CHUNK));
        }
        if read < size {
            return Err(McapError::UnexpectedEof);
        }
        match opcode {
            op::DATA_END => self.past_data_end = true,
            op::FOOTER => {
                let mut magic = [0u8; 8];
                if read_up_to(&mut self.file, &mut magic)? < magic.len() || magic != *mcap::MAGIC {
                    return Err(McapError::BadMagic);
                }
                return Ok(None);
            }
            _ => {}
        }
        Ok(Some(opcode))
    }
}

/// Fills `buf` from `r` as far as it goes; returns the bytes read (fewer at the end).
fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> McapResult<usize> {
    let (n, result) = fill(r, buf);
    result?;
    Ok(n)
}

/// Reads into `buf` until it is full or `r` ends: the bytes read, and the error that
/// stopped it early (retrying interrupted reads).
fn fill(r: &mut impl Read, buf: &mut [u8]) -> (usize, std::io::Result<()>) {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return (n, Err(e)),
        }
    }
    (n, Ok(()))
}

/// Takes in a schema or channel record; hands a message of one of `topics` to `visit`.
/// Returns `None` for any other record (and for everything after the data end), an error
/// for a record that does not parse or a message of an unknown channel.
fn message_of<R>(
    channels: &mut ChannelAccumulator<'static>,
    topics: &[String],
    past_data_end: bool,
    opcode: u8,
    body: &[u8],
    visit: &mut impl FnMut(RawMessage<'_>) -> R,
) -> Option<McapResult<R>> {
    if past_data_end || !matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
        return None;
    }
    let record = match mcap::parse_record(opcode, body) {
        Ok(record) => record,
        Err(e) => return Some(Err(e)),
    };
    let added = match record {
        Record::Schema { header, data } => channels.add_schema_from_slice(header, &data),
        Record::Channel(channel) => channels.add_channel(channel),
        Record::Message { header, data } => {
            let Some(channel) = channels.get(header.channel_id) else {
                return Some(Err(McapError::UnknownChannel(header.sequence, header.channel_id)));
            };
            if !topics.iter().any(|t| *t == channel.topic) {
                return None;
            }
            return Some(Ok(visit(RawMessage { channel, log_time_ns: header.log_time, data: &data })));
        }
        _ => Ok(()),
    };
    added.err().map(Err)
}

/// The fields of a chunk record before its records (MCAP specification, "Chunk").
struct ChunkHeader<'a> {
    uncompressed_size: usize,
    uncompressed_crc: u32,
    compression: &'a [u8],
    /// The compressed records (all of them when `whole`, else those that are there).
    records: &'a [u8],
}

/// Takes apart a chunk record's body; with `whole`, it must hold all the records its
/// header declares.
fn chunk_header(body: &[u8], whole: bool) -> McapResult<ChunkHeader<'_>> {
    let u64_at = |at: usize| body.get(at..at + 8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or_default()));
    let u32_at = |at: usize| body.get(at..at + 4).map(|b| u32::from_le_bytes(b.try_into().unwrap_or_default()));
    let uncompressed_size = u64_at(16).ok_or(McapError::UnexpectedEof)?;
    let uncompressed_crc = u32_at(24).ok_or(McapError::UnexpectedEof)?;
    let name_len = u32_at(28).ok_or(McapError::UnexpectedEof)? as usize;
    let compression = body.get(32..32 + name_len).ok_or(McapError::UnexpectedEof)?;
    let compressed_size = u64_at(32 + name_len).ok_or(McapError::UnexpectedEof)?;
    let records = &body[40 + name_len..];
    let uncompressed_size = usize::try_from(uncompressed_size)
        .ok()
        .filter(|&n| n <= MAX_RECORD_BYTES)
        .ok_or(McapError::ChunkTooLarge(uncompressed_size))?;
    let records = match usize::try_from(compressed_size).ok().filter(|&n| n <= records.len()) {
        Some(n) => &records[..n],
        None if !whole => records,
        None => return Err(McapError::BadChunkLength { header: compressed_size, available: records.len() as u64 }),
    };
    Ok(ChunkHeader { uncompressed_size, uncompressed_crc, compression, records })
}

/// Decompresses the chunk record `body` into `out` (its records). With `whole`, all of
/// them must be there, and the CRC is checked when the chunk has one; otherwise `out`
/// gets what decompresses of the part there is (an error says where it stopped).
fn decompress_chunk(body: &[u8], out: &mut Vec<u8>, zstd: &mut WholeChunkZstd, whole: bool) -> McapResult<()> {
    let chunk = chunk_header(body, whole)?;
    let size = chunk.uncompressed_size;
    out.clear();
    out.resize(size, 0);
    let wrote = match chunk.compression {
        b"" => {
            let n = chunk.records.len().min(size);
            out[..n].copy_from_slice(&chunk.records[..n]);
            if whole && chunk.records.len() != size {
                out.clear();
                return Err(McapError::DecompressionError(format!(
                    "an uncompressed chunk of {} bytes declares {size}",
                    chunk.records.len()
                )));
            }
            Ok(n)
        }
        b"zstd" => {
            let decoded = decode_into(zstd, chunk.records, out);
            zstd.reset()?;
            decoded
        }
        b"lz4" => lz4_into(chunk.records, out),
        other => Err((0, McapError::UnsupportedCompression(String::from_utf8_lossy(other).into_owned()))),
    };
    let (n, error) = match wrote {
        Ok(n) => (n, None),
        Err((n, e)) => (n, Some(e)),
    };
    out.truncate(n);
    if let Some(e) = error {
        return Err(e);
    }
    if whole && chunk.uncompressed_crc != 0 {
        let calculated = crc32fast::hash(out);
        if calculated != chunk.uncompressed_crc {
            out.clear();
            return Err(McapError::BadChunkCrc { saved: chunk.uncompressed_crc, calculated });
        }
    }
    Ok(())
}

/// What a decoder wrote, or how far it got and why it stopped.
type Decoded = Result<usize, (usize, McapError)>;

/// Fills `out` from the zstd data `src` (as the `mcap` crate drives a decompressor: until
/// `out` is full; a call that makes no progress is an error).
fn decode_into(d: &mut impl Decompressor, src: &[u8], out: &mut [u8]) -> Decoded {
    let (mut read, mut wrote) = (0, 0);
    while wrote < out.len() {
        let step = d.decompress(&src[read..], &mut out[wrote..]).map_err(|e| (wrote, e))?;
        if step.consumed == 0 && step.wrote == 0 || step.consumed > src.len() - read || step.wrote > out.len() - wrote {
            let e = McapError::DecompressionError("the zstd data ends before the chunk's declared size".into());
            return Err((wrote, e));
        }
        (read, wrote) = (read + step.consumed, wrote + step.wrote);
    }
    Ok(wrote)
}

/// Fills `out` from the lz4 frame `src`.
fn lz4_into(src: &[u8], out: &mut [u8]) -> Decoded {
    let error = |wrote: usize, e: std::io::Error| (wrote, McapError::DecompressionError(format!("lz4: {e}")));
    let mut decoder = lz4::Decoder::new(src).map_err(|e| error(0, e))?;
    let (wrote, result) = fill(&mut decoder, out);
    result.map_err(|e| error(wrote, e))?;
    if wrote < out.len() {
        return Err(error(wrote, std::io::ErrorKind::UnexpectedEof.into()));
    }
    Ok(wrote)
}

#[cfg(test)]
mod tests {
    use super::*;
    use mcap::records::MessageHeader;
    use std::collections::BTreeMap;

    /// Payload of message `i`: 3 kB that compress a little.
    fn payload(i: u64) -> Vec<u8> {
        (0..3000u64).map(|k| ((k * 7 + i * 13) % 251) as u8 / 4).collect()
    }

    /// A file of `n` messages on `/t` in one chunk, and where that chunk record starts.
    fn one_chunk(compression: Option<mcap::Compression>, n: u64) -> (Vec<u8>, usize) {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut w =
            mcap::WriteOptions::new().compression(compression).chunk_size(None).create(&mut out).expect("writer");
        let schema = w.add_schema("t", "jsonschema", b"{}").expect("schema");
        let channel = w.add_channel(schema, "/t", "json", &BTreeMap::new()).expect("channel");
        for i in 0..n {
            let header = MessageHeader { channel_id: channel, sequence: i as u32, log_time: i, publish_time: i };
            w.write_to_known_channel(&header, &payload(i)).expect("message");
        }
        w.finish().expect("finish");
        drop(w);
        let bytes = out.into_inner();
        let chunk = (8..bytes.len()).find(|&p| bytes[p] == op::CHUNK).expect("a chunk");
        (bytes, chunk)
    }

    /// Streams `bytes` (written to a file named after `name`, which must be unique
    /// among the tests: they run in parallel): the log times of the messages, checked
    /// against their payloads, and how it ended.
    fn stream(bytes: &[u8], name: &str) -> (Vec<u64>, Option<McapError>) {
        let path = std::env::temp_dir().join(format!("mrsmap-stream-{name}-{}.mcap", std::process::id()));
        std::fs::write(&path, bytes).expect("write");
        let mut file = File::open(&path).expect("open");
        let mut magic = [0u8; 8];
        file.read_exact(&mut magic).expect("magic");
        let mut s = Streamed::new(file, vec!["/t".to_string()]);
        let mut times = Vec::new();
        let end = loop {
            match s.next(&mut |m| (m.log_time_ns, m.data.to_vec())) {
                Some(Ok((t, data))) => {
                    assert_eq!(data, payload(t), "payload of {t}");
                    times.push(t);
                }
                Some(Err(e)) => break Some(e),
                None => break None,
            }
        };
        let _ = std::fs::remove_file(&path);
        (times, end)
    }

    const COMPRESSIONS: [(Option<mcap::Compression>, &str); 3] =
        [(None, "none"), (Some(mcap::Compression::Zstd), "zstd"), (Some(mcap::Compression::Lz4), "lz4")];

    #[test]
    fn reads_every_message_of_an_intact_file() {
        for (compression, name) in COMPRESSIONS {
            let (bytes, _) = one_chunk(compression, 20);
            let (times, end) = stream(&bytes, &format!("intact-{name}"));
            assert_eq!(times, (0..20).collect::<Vec<u64>>(), "{name}");
            assert!(end.is_none(), "{name}: {end:?}");
        }
    }

    #[test]
    fn a_file_cut_inside_a_chunk_gives_the_messages_before_the_cut() {
        // 300 kB: zstd decodes in blocks of up to 128 kB, so a cut loses the block it falls in.
        for (compression, name) in COMPRESSIONS {
            let (bytes, chunk) = one_chunk(compression, 100);
            let len = u64::from_le_bytes(bytes[chunk + 1..chunk + 9].try_into().expect("8 bytes")) as usize;
            let cut = chunk + OPCODE_LEN_SIZE + len * 6 / 10;
            let (times, end) = stream(&bytes[..cut], &format!("cut-{name}"));
            assert!((3..100).contains(&times.len()), "{name}: {} messages", times.len());
            assert_eq!(times, (0..times.len() as u64).collect::<Vec<u64>>(), "{name}");
            assert!(matches!(end, Some(McapError::UnexpectedEof)), "{name}: {end:?}");
        }
    }

    #[test]
    fn a_record_longer_than_its_uncompressed_chunk_is_an_error() {
        // Found by fuzzing (fuzz/mcap_recording): the `mcap` crate's reader subtracted this
        // length from what was left of the chunk and overflowed.
        let (mut bytes, chunk) = one_chunk(None, 4);
        let first_record = chunk + OPCODE_LEN_SIZE + 40; // chunk header with compression ""
        bytes[first_record + 1..first_record + 9].copy_from_slice(&1_000_000u64.to_le_bytes());
        bytes[chunk + OPCODE_LEN_SIZE + 24..][..4].fill(0); // no CRC, as in the file the fuzzer made
        let (times, end) = stream(&bytes, "overlong");
        assert!(times.is_empty());
        assert!(matches!(end, Some(McapError::UnexpectedEoc)), "{end:?}");
    }

    #[test]
    fn a_chunk_whose_crc_fails_is_an_error() {
        let (mut bytes, chunk) = one_chunk(None, 4);
        let last = chunk + OPCODE_LEN_SIZE + 40 + 100;
        bytes[last] ^= 0x55;
        let (times, end) = stream(&bytes, "crc");
        assert!(times.is_empty());
        assert!(matches!(end, Some(McapError::BadChunkCrc { .. })), "{end:?}");
    }
}
