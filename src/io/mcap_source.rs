//! The messages of chosen topics of an MCAP file, one at a time and in log-time order,
//! with memory bounded by the chunk size (never the file size).
//!
//! A file with a summary and chunk indexes is read through the index (only the chunks
//! that hold the chosen topics are read, by seeking). A file without one — a recording
//! cut off before it was finished, or an unchunked file — is streamed from the start; if
//! it is damaged, the messages before the damage are delivered and the damage reported.

use super::mcap_stream::Streamed;
use super::zstd_chunk::WholeChunkZstd;
use mcap::sans_io::indexed_reader::{IndexedReadEvent, IndexedReader, IndexedReaderOptions};
use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
use mcap::{Channel, McapError, Summary};
use std::collections::HashMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;
use std::sync::Arc;

/// The largest record (message, or chunk compressed or not) read: 256 MiB, four times a
/// 4096 × 4096 RGBA image, the largest image read. A damaged length field then gives an
/// error instead of an allocation of exabytes (which aborts the process).
pub const MAX_RECORD_BYTES: usize = 256 << 20;

/// How the file is being read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReadMode {
    /// Through the summary's chunk index, seeking.
    Indexed,
    /// From start to end (no usable summary).
    Streamed,
}

/// One message: its channel, log time, and payload (lent for one call).
#[derive(Debug)]
pub struct RawMessage<'a> {
    /// The channel (topic, schema, encoding).
    pub channel: Arc<Channel<'static>>,
    /// Log time (ns).
    pub log_time_ns: u64,
    /// The serialised message.
    pub data: &'a [u8],
}

/// Reading through the chunk index; a damaged chunk is skipped (and reported) and the
/// reading goes on with the other chunks.
///
/// Chunks may overlap in log time, so when one turns out damaged, other chunks already
/// read may still hold messages not yet delivered. The reading then restarts over every
/// undamaged chunk that can hold such messages (ending at or after the last delivered log
/// time) and passes over what was delivered already: messages before that time, and at
/// it the ones recorded in `delivered_at_last`. Only the damaged chunk's own messages are
/// lost.
struct Indexed {
    file: File,
    /// Bytes in the file: a chunk the index places beyond them is damaged.
    file_len: u64,
    summary: Summary,
    topics: Vec<String>,
    reader: IndexedReader,
    chunk: Vec<u8>,
    /// Offsets of the chunks requested so far (the last one is being read).
    requested: Vec<u64>,
    /// Offsets of the chunks found damaged.
    damaged: Vec<u64>,
    /// Log time of the last delivered message.
    last_time: Option<u64>,
    /// The messages delivered at `last_time`.
    delivered_at_last: Vec<MessageKey>,
    /// After a restart, until a message after `last_time` comes: those of
    /// `delivered_at_last` not yet met again.
    resuming: Option<Vec<MessageKey>>,
}

/// What tells apart messages of one log time: channel, sequence, publish time, length.
type MessageKey = (u16, u32, u64, usize);

impl Indexed {
    fn new(file: File, file_len: u64, summary: Summary, topics: Vec<String>, reader: IndexedReader) -> Self {
        Indexed {
            file,
            file_len,
            summary,
            topics,
            reader,
            chunk: Vec::new(),
            requested: Vec::new(),
            damaged: Vec::new(),
            last_time: None,
            delivered_at_last: Vec::new(),
            resuming: None,
        }
    }

    fn options(topics: &[String]) -> IndexedReaderOptions {
        IndexedReaderOptions::new().include_topics(topics.iter().cloned()).with_record_length_limit(MAX_RECORD_BYTES)
    }

    /// The reader over `summary`'s chunks, with zstd chunks decoded whole (`zstd_chunk`).
    fn reader(summary: &Summary, topics: &[String]) -> mcap::McapResult<IndexedReader> {
        let mut reader = IndexedReader::new_with_options(summary, Self::options(topics))?;
        reader.add_decompressor(WholeChunkZstd::default())?;
        Ok(reader)
    }

    /// The next message, handed to `visit` while the reader lends its bytes.
    fn next<R>(&mut self, visit: &mut impl FnMut(RawMessage<'_>) -> R) -> Next<R> {
        loop {
            match self.reader.next_event()? {
                Err(e) => return Some(Err(e)),
                Ok(IndexedReadEvent::ReadChunkRequest { offset, length }) => {
                    self.requested.push(offset);
                    if offset.checked_add(length as u64).is_none_or(|end| end > self.file_len) {
                        return Some(Err(McapError::UnexpectedEof));
                    }
                    self.chunk.resize(length, 0);
                    let read =
                        self.file.seek(SeekFrom::Start(offset)).and_then(|_| self.file.read_exact(&mut self.chunk));
                    if let Err(e) = read {
                        return Some(Err(e.into()));
                    }
                    if let Err(e) = self.reader.insert_chunk_record_data(offset, &self.chunk) {
                        return Some(Err(e));
                    }
                }
                Ok(IndexedReadEvent::Message { header, data }) => {
                    let key = (header.channel_id, header.sequence, header.publish_time, data.len());
                    if delivered_before(&mut self.resuming, self.last_time, header.log_time, key) {
                        continue;
                    }
                    let Some(channel) = self.summary.channels.get(&header.channel_id) else {
                        return Some(Err(McapError::UnknownChannel(header.sequence, header.channel_id)));
                    };
                    if self.last_time != Some(header.log_time) {
                        self.last_time = Some(header.log_time);
                        self.delivered_at_last.clear();
                    }
                    self.delivered_at_last.push(key);
                    return Some(Ok(visit(RawMessage {
                        channel: channel.clone(),
                        log_time_ns: header.log_time,
                        data,
                    })));
                }
            }
        }
    }

    /// After damage in the chunk read last: restarts over the undamaged chunks that may
    /// still hold undelivered messages. Returns `false` if there is none left (or the
    /// damage cannot be pinned on a chunk not already skipped).
    fn skip_damaged_chunk(&mut self) -> bool {
        let Some(&offset) = self.requested.last() else { return false };
        if self.damaged.contains(&offset) {
            return false;
        }
        self.damaged.push(offset);
        let mut rest = self.summary.clone();
        let (requested, damaged, last_time) = (&self.requested, &self.damaged, self.last_time);
        rest.chunk_indexes.retain(|c| {
            c.compressed_data_offset().is_ok_and(|offset| {
                !damaged.contains(&offset)
                    && (!requested.contains(&offset) || last_time.is_none_or(|t| c.message_end_time >= t))
            })
        });
        if rest.chunk_indexes.is_empty() {
            return false;
        }
        match Self::reader(&rest, &self.topics) {
            Ok(reader) => {
                self.reader = reader;
                self.resuming = Some(self.delivered_at_last.clone());
                true
            }
            Err(_) => false,
        }
    }
}

/// After a restart over the chunks (`resuming`, see [`Indexed`]): whether a message was
/// delivered before it. Each delivered message of the last time is matched once; the
/// first message after that time ends the resumption.
fn delivered_before(
    resuming: &mut Option<Vec<MessageKey>>,
    last_time: Option<u64>,
    log_time: u64,
    key: MessageKey,
) -> bool {
    let (Some(pending), Some(last)) = (resuming.as_mut(), last_time) else { return false };
    if log_time > last {
        *resuming = None;
        return false;
    }
    if log_time < last {
        return true;
    }
    match pending.iter().position(|k| *k == key) {
        Some(i) => {
            pending.swap_remove(i);
            true
        }
        None => false,
    }
}

enum Source {
    Indexed(Box<Indexed>),
    Streamed(Box<Streamed>),
}

/// Messages of the chosen topics of one MCAP file.
pub struct McapSource {
    source: Source,
    mode: ReadMode,
    counts: HashMap<String, u64>,
    /// Every channel's topic and schema name, sorted, when the file has a summary.
    channels: Option<Vec<(String, String)>>,
    skipped: Vec<String>,
    done: bool,
}

impl std::fmt::Debug for McapSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapSource").field("mode", &self.mode).finish_non_exhaustive()
    }
}

/// Reads the summary section, if the file has a usable one.
fn read_summary(file: &mut File, file_len: u64) -> Result<Option<Summary>, McapError> {
    let options = SummaryReaderOptions::default().with_file_size(file_len).with_record_length_limit(MAX_RECORD_BYTES);
    let mut reader = SummaryReader::new_with_options(options);
    while let Some(event) = reader.next_event() {
        match event? {
            SummaryReadEvent::ReadRequest(n) => {
                let read = file.read(reader.insert(n))?;
                reader.notify_read(read);
            }
            SummaryReadEvent::SeekRequest(to) => reader.notify_seeked(file.seek(to)?),
        }
    }
    Ok(reader.finish())
}

impl McapSource {
    /// Opens `path` for the messages of `topics`. Fails only if the file cannot be opened
    /// or does not start like an MCAP file.
    pub fn open(path: &Path, topics: &[&str]) -> Result<Self, McapError> {
        let mut file = File::open(path)?;
        let mut magic = [0u8; 8];
        match file.read_exact(&mut magic) {
            Ok(()) if magic == *mcap::MAGIC => {}
            // Not a file that can be read (a folder, a device error): said as such.
            Err(e) if e.kind() != std::io::ErrorKind::UnexpectedEof => return Err(e.into()),
            _ => return Err(McapError::BadMagic),
        }
        let file_len = file.metadata()?.len();
        // A missing or damaged summary is not an error: the file is streamed instead.
        let summary = read_summary(&mut file, file_len).ok().flatten().filter(|s| !s.chunk_indexes.is_empty());
        let mut counts = HashMap::new();
        if let Some(s) = &summary {
            for (id, n) in s.stats.iter().flat_map(|st| st.channel_message_counts.iter()) {
                if let Some(channel) = s.channels.get(id) {
                    *counts.entry(channel.topic.clone()).or_insert(0) += n;
                }
            }
        }
        let channels = summary.as_ref().map(|s| {
            let mut all: Vec<(String, String)> = s
                .channels
                .values()
                .map(|c| (c.topic.clone(), c.schema.as_ref().map_or_else(String::new, |schema| schema.name.clone())))
                .collect();
            all.sort();
            all.dedup();
            all
        });
        let topics: Vec<String> = topics.iter().map(|t| t.to_string()).collect();
        // An index the reader refuses (a chunk larger than any we read) counts as damaged.
        let indexed = summary.and_then(|s| Indexed::reader(&s, &topics).ok().map(|reader| (s, reader)));
        let source = match indexed {
            Some((summary, reader)) => Source::Indexed(Box::new(Indexed::new(file, file_len, summary, topics, reader))),
            None => {
                file.seek(SeekFrom::Start(mcap::MAGIC.len() as u64))?;
                Source::Streamed(Box::new(Streamed::new(file, topics)))
            }
        };
        let mode = match source {
            Source::Indexed(_) => ReadMode::Indexed,
            Source::Streamed(_) => ReadMode::Streamed,
        };
        Ok(McapSource { source, mode, counts, channels, skipped: Vec::new(), done: false })
    }

    /// Every channel's topic and schema name (sorted), if the file has a summary, which
    /// lists them all; `None` for a file read as a stream.
    pub fn channels(&self) -> Option<&[(String, String)]> {
        self.channels.as_deref()
    }

    /// How the file is read.
    pub fn mode(&self) -> ReadMode {
        self.mode
    }

    /// The number of messages on `topic`, if the summary says.
    pub fn message_count(&self, topic: &str) -> Option<u64> {
        self.counts.get(topic).copied()
    }

    /// Damaged chunks that were skipped (indexed reading), with what was wrong.
    pub fn skipped_chunks(&self) -> &[String] {
        &self.skipped
    }

    /// The next message of a chosen topic, handed to `visit` (called once, with the
    /// message) without a copy: its bytes are lent for the call (in indexed reading, those
    /// of the decompressed chunk). `None` at the end; an error where the file is damaged
    /// and cannot be read further (after which the source is finished). In indexed
    /// reading a damaged chunk is skipped ([`Self::skipped_chunks`]) instead.
    pub fn next_message_with<R>(&mut self, mut visit: impl FnMut(RawMessage<'_>) -> R) -> Option<Result<R, McapError>> {
        if self.done {
            return None;
        }
        let next = match &mut self.source {
            Source::Indexed(indexed) => loop {
                match indexed.next(&mut visit) {
                    Some(Err(e)) => {
                        let offset = indexed.requested.last().copied().unwrap_or(0);
                        self.skipped.push(format!("chunk at byte {offset}: {e}"));
                        if indexed.skip_damaged_chunk() {
                            continue;
                        }
                        break None;
                    }
                    other => break other,
                }
            },
            Source::Streamed(streamed) => streamed.next(&mut visit),
        };
        // The end, or damage that cannot be read past: the source is finished.
        if !matches!(next, Some(Ok(_))) {
            self.done = true;
        }
        next
    }
}

type Next<R> = Option<Result<R, McapError>>;

#[cfg(test)]
mod tests {
    use super::*;
    use mcap::records::MessageHeader;
    use std::collections::BTreeMap;

    /// Log times (ns) of the chunks of the test file, in file order: the first three
    /// overlap in time (the first two at the same times), the fourth follows.
    fn chunk_times() -> [Vec<u64>; 4] {
        let steps = |from: u64, to: u64| (from..=to).step_by(10).collect::<Vec<u64>>();
        [steps(0, 90), steps(0, 90), steps(50, 140), steps(200, 290)]
    }

    /// An indexed file with one zstd chunk per entry of `chunk_times` of messages on `/t`
    /// whose payload is their log time; returns its bytes.
    fn overlapping_chunks() -> Vec<u8> {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(None)
            .create(&mut out)
            .expect("writer");
        let schema = w.add_schema("t", "jsonschema", b"{}").expect("schema");
        let channel = w.add_channel(schema, "/t", "json", &BTreeMap::new()).expect("channel");
        let mut sequence = 0;
        for times in chunk_times() {
            for t in times {
                let header = MessageHeader { channel_id: channel, sequence, log_time: t, publish_time: t };
                w.write_to_known_channel(&header, &t.to_le_bytes()).expect("message");
                sequence += 1;
            }
            w.flush().expect("ends the chunk");
        }
        w.finish().expect("finish");
        drop(w);
        out.into_inner()
    }

    /// Log times read from `path` (checked against their payloads) and chunks skipped.
    fn read_all(path: &Path) -> (Vec<u64>, usize) {
        let mut source = McapSource::open(path, &["/t"]).expect("opens");
        assert_eq!(source.mode(), ReadMode::Indexed);
        let mut times = Vec::new();
        while let Some(message) = source.next_message_with(|m| (m.log_time_ns, m.data.to_vec())) {
            let (log_time_ns, data) = message.expect("intact chunks read");
            assert_eq!(data, log_time_ns.to_le_bytes(), "payload of {log_time_ns}");
            times.push(log_time_ns);
        }
        (times, source.skipped_chunks().len())
    }

    #[test]
    fn an_absurd_record_length_is_an_error_not_an_allocation() {
        // Found by fuzzing (fuzz/mcap_recording): a damaged length field made the streaming
        // reader reserve exabytes, and the process aborted.
        let mut bytes = overlapping_chunks();
        bytes.truncate(bytes.len() / 2); // no summary: streamed
        bytes[9..17].copy_from_slice(&0x6174_6164_040a_189f_u64.to_le_bytes()); // the header record's length
        let path = std::env::temp_dir().join(format!("mrsmap-absurd-{}.mcap", std::process::id()));
        std::fs::write(&path, &bytes).expect("write");
        let mut source = McapSource::open(&path, &["/t"]).expect("opens");
        assert_eq!(source.mode(), ReadMode::Streamed);
        let e = source.next_message_with(|_| ()).expect("an event").expect_err("damaged");
        assert!(e.to_string().to_lowercase().contains("too large") || e.to_string().contains("length"), "{e}");
        assert!(source.next_message_with(|_| ()).is_none());
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn a_damaged_chunk_loses_only_its_own_messages_when_chunks_overlap_in_time() {
        let bytes = overlapping_chunks();
        let dir = std::env::temp_dir().join(format!("mrsmap-overlap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let summary = mcap::Summary::read(&bytes).expect("summary").expect("has one");
        let mut chunks = summary.chunk_indexes.clone();
        chunks.sort_by_key(|c| c.chunk_start_offset);
        assert_eq!(chunks.len(), 4);
        // Intact; each chunk damaged in turn; the first and the third together (the third
        // is found damaged after messages of the first two at its start time went out).
        for damaged in [vec![], vec![0], vec![1], vec![2], vec![3], vec![0, 2]] {
            let mut bad = bytes.clone();
            for &k in &damaged {
                let chunk: &mcap::records::ChunkIndex = &chunks[k];
                let start = chunk.compressed_data_offset().expect("offset") as usize;
                bad[start..start + chunk.compressed_size as usize].fill(0xA5);
            }
            let path = dir.join("file.mcap");
            std::fs::write(&path, &bad).expect("write");
            let mut expected: Vec<u64> = chunk_times()
                .into_iter()
                .enumerate()
                .filter(|(k, _)| !damaged.contains(k))
                .flat_map(|(_, times)| times)
                .collect();
            expected.sort();
            assert_eq!(read_all(&path), (expected, damaged.len()), "chunks {damaged:?} damaged");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
