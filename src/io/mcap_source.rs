//! The messages of chosen topics of an MCAP file, one at a time and in log-time order,
//! with memory bounded by the chunk size (never the file size).
//!
//! A file with a summary and chunk indexes is read through the index (only the chunks
//! that hold the chosen topics are read, by seeking). A file without one — a recording
//! cut off before it was finished, or an unchunked file — is streamed from the start; if
//! it is damaged, the messages before the damage are delivered and the damage reported.

use mcap::sans_io::indexed_reader::{IndexedReadEvent, IndexedReader, IndexedReaderOptions};
use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader};
use mcap::{Channel, McapError, Summary};
use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;
use std::sync::Arc;

/// How the file is being read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReadMode {
    /// Through the summary's chunk index, seeking.
    Indexed,
    /// From start to end (no usable summary).
    Streamed,
}

/// One message: its channel, log time, and payload (valid until the next call).
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
/// reading goes on with the chunks not yet read.
struct Indexed {
    file: File,
    summary: Summary,
    topics: Vec<String>,
    reader: IndexedReader,
    chunk: Vec<u8>,
    /// Offsets of the chunks requested so far (the last one is being read).
    requested: Vec<u64>,
    /// `requested.len()` at the last skip.
    requested_at_skip: usize,
}

impl Indexed {
    fn new(file: File, summary: Summary, topics: &[&str]) -> Result<Self, McapError> {
        let topics: Vec<String> = topics.iter().map(|t| t.to_string()).collect();
        let reader = IndexedReader::new_with_options(&summary, Self::options(&topics))?;
        Ok(Indexed { file, summary, topics, reader, chunk: Vec::new(), requested: Vec::new(), requested_at_skip: 0 })
    }

    fn options(topics: &[String]) -> IndexedReaderOptions {
        IndexedReaderOptions::new().include_topics(topics.iter().cloned())
    }

    fn next(&mut self, payload: &mut Vec<u8>) -> Next {
        loop {
            match self.reader.next_event()? {
                Err(e) => return Some(Err(e)),
                Ok(IndexedReadEvent::ReadChunkRequest { offset, length }) => {
                    self.requested.push(offset);
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
                    let Some(channel) = self.summary.channels.get(&header.channel_id) else {
                        return Some(Err(McapError::UnknownChannel(header.sequence, header.channel_id)));
                    };
                    payload.clear();
                    payload.extend_from_slice(data);
                    return Some(Ok((channel.clone(), header.log_time)));
                }
            }
        }
    }

    /// After damage in the chunk read last: a reader over the chunks not requested yet.
    /// Returns `false` if there is none left (or nothing was read since the last skip).
    fn skip_damaged_chunk(&mut self) -> bool {
        if self.requested.len() == self.requested_at_skip {
            return false;
        }
        self.requested_at_skip = self.requested.len();
        let mut rest = self.summary.clone();
        rest.chunk_indexes.retain(|c| c.compressed_data_offset().is_ok_and(|offset| !self.requested.contains(&offset)));
        if rest.chunk_indexes.is_empty() {
            return false;
        }
        match IndexedReader::new_with_options(&rest, Self::options(&self.topics)) {
            Ok(reader) => {
                self.reader = reader;
                true
            }
            Err(_) => false,
        }
    }
}

enum Source {
    Indexed(Box<Indexed>),
    Streamed { reader: Box<mcap::io::MessageReader<BufReader<File>>>, topics: Vec<String> },
}

/// Messages of the chosen topics of one MCAP file.
pub struct McapSource {
    source: Source,
    mode: ReadMode,
    counts: HashMap<String, u64>,
    skipped: Vec<String>,
    payload: Vec<u8>,
    done: bool,
}

impl std::fmt::Debug for McapSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapSource").field("mode", &self.mode).finish_non_exhaustive()
    }
}

/// Reads the summary section, if the file has a usable one.
fn read_summary(file: &mut File) -> Result<Option<Summary>, McapError> {
    let mut reader = SummaryReader::new();
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
        if file.read_exact(&mut magic).is_err() || magic != *mcap::MAGIC {
            return Err(McapError::BadMagic);
        }
        // A missing or damaged summary is not an error: the file is streamed instead.
        let summary = read_summary(&mut file).ok().flatten().filter(|s| !s.chunk_indexes.is_empty());
        let mut counts = HashMap::new();
        if let Some(s) = &summary {
            for (id, n) in s.stats.iter().flat_map(|st| st.channel_message_counts.iter()) {
                if let Some(channel) = s.channels.get(id) {
                    *counts.entry(channel.topic.clone()).or_insert(0) += n;
                }
            }
        }
        let source = match summary {
            Some(summary) => Source::Indexed(Box::new(Indexed::new(file, summary, topics)?)),
            None => {
                file.seek(SeekFrom::Start(0))?;
                let reader = mcap::io::MessageReader::new(BufReader::with_capacity(1 << 20, file));
                Source::Streamed { reader: Box::new(reader), topics: topics.iter().map(|t| t.to_string()).collect() }
            }
        };
        let mode = match source {
            Source::Indexed(_) => ReadMode::Indexed,
            Source::Streamed { .. } => ReadMode::Streamed,
        };
        Ok(McapSource { source, mode, counts, skipped: Vec::new(), payload: Vec::new(), done: false })
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

    /// The next message of a chosen topic; `None` at the end; an error where the file is
    /// damaged and cannot be read further (after which the source is finished). In
    /// indexed reading a damaged chunk is skipped ([`Self::skipped_chunks`]) instead.
    pub fn next_message(&mut self) -> Option<Result<RawMessage<'_>, McapError>> {
        if self.done {
            return None;
        }
        let next = match &mut self.source {
            Source::Indexed(indexed) => loop {
                match indexed.next(&mut self.payload) {
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
            Source::Streamed { reader, topics } => next_streamed(reader, topics, &mut self.payload),
        };
        match next {
            Some(Ok((channel, log_time_ns))) => Some(Ok(RawMessage { channel, log_time_ns, data: &self.payload })),
            Some(Err(e)) => {
                self.done = true;
                Some(Err(e))
            }
            None => {
                self.done = true;
                None
            }
        }
    }
}

type Next = Option<Result<(Arc<Channel<'static>>, u64), McapError>>;

fn next_streamed(
    reader: &mut mcap::io::MessageReader<BufReader<File>>,
    topics: &[String],
    payload: &mut Vec<u8>,
) -> Next {
    loop {
        match reader.next()? {
            Err(e) => return Some(Err(e)),
            Ok(message) if topics.iter().any(|t| *t == message.channel.topic) => {
                *payload = message.data.into_owned();
                return Some(Ok((message.channel, message.log_time)));
            }
            Ok(_) => {}
        }
    }
}
