//! RGB-D frames from an MCAP recording: colour and depth images paired by their header
//! stamps (within 20 ms, as the TUM tools associate), with the camera from the latest
//! calibration message. Buffers are reused from frame to frame.

use super::image_msg::{ImageHolder, MessageKind, decode_calibration, decode_image, to_depth16, to_rgb8};
use super::mcap_source::{McapSource, RawMessage, ReadMode};
use crate::frame::{OwnedFrame, RgbdFrame};
use crate::geometry::CameraModel;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The default ROS 2 topics of an RGB-D camera (depth registered to colour).
pub const DEFAULT_COLOR_TOPIC: &str = "/camera/color/image_raw";
/// See [`DEFAULT_COLOR_TOPIC`].
pub const DEFAULT_DEPTH_TOPIC: &str = "/camera/depth/image_raw";
/// See [`DEFAULT_COLOR_TOPIC`].
pub const DEFAULT_CAMERA_INFO_TOPIC: &str = "/camera/color/camera_info";

/// Colour and depth images further apart than this are not paired (ns).
pub const PAIRING_TOLERANCE_NS: u64 = 20_000_000;

/// Which topics carry the images and the calibration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordingTopics {
    /// Colour images.
    pub color: String,
    /// Depth images, registered to colour.
    pub depth: String,
    /// Calibration of the colour camera.
    pub camera_info: String,
}

impl Default for RecordingTopics {
    fn default() -> Self {
        RecordingTopics {
            color: DEFAULT_COLOR_TOPIC.into(),
            depth: DEFAULT_DEPTH_TOPIC.into(),
            camera_info: DEFAULT_CAMERA_INFO_TOPIC.into(),
        }
    }
}

/// Why a recording could not be read.
#[derive(Debug, Error)]
pub enum RecordingError {
    /// The file cannot be opened (missing, no permission, ...).
    #[error("cannot open {path}: {source}")]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not MCAP, or its start cannot be read as such.
    #[error("{path}: cannot read as MCAP: {source}")]
    Open {
        /// The file.
        path: PathBuf,
        /// Why.
        source: mcap::McapError,
    },
    /// A message cannot be used.
    #[error("topic {topic}, message {index}: {reason}")]
    Message {
        /// Its topic.
        topic: String,
        /// Its index on that topic (0-based).
        index: u64,
        /// What is wrong.
        reason: String,
    },
    /// A chosen topic is not in the recording (its summary lists every topic).
    #[error(
        "{path}: no {what} topic {topic:?} in the recording (give the right one with --{flag}); its topics: {available}"
    )]
    NoSuchTopic {
        /// The file.
        path: PathBuf,
        /// What the topic was to carry: "colour", "depth", "calibration".
        what: &'static str,
        /// The option that names it (`color-topic`, ...).
        flag: &'static str,
        /// The topic asked for.
        topic: String,
        /// The recording's topics with their schemas.
        available: String,
    },
    /// Images arrived before any calibration.
    #[error(
        "topic {topic}, message {index}: no camera calibration (CameraInfo) on {camera_info_topic} before it; name the calibration topic or give --camera"
    )]
    NoCalibration {
        /// The image topic.
        topic: String,
        /// The image's index.
        index: u64,
        /// Where calibration was expected.
        camera_info_topic: String,
    },
}

/// The file ended or broke before its end; the frames before were delivered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Damage {
    /// What the MCAP reader found.
    pub reason: String,
    /// Messages of the chosen topics read before the damage.
    pub messages_before: u64,
}

struct Pending<T> {
    stamp_ns: u64,
    index: u64,
    width: usize,
    height: usize,
    depth_scale_m: f64,
    pixels: Vec<T>,
}

/// Up to a few images waiting for their partner, with recycled buffers.
struct Queue<T> {
    items: VecDeque<Pending<T>>,
    free: Vec<Vec<T>>,
}

impl<T> Queue<T> {
    fn new() -> Self {
        Queue { items: VecDeque::new(), free: Vec::new() }
    }
    fn buffer(&mut self) -> Vec<T> {
        self.free.pop().unwrap_or_default()
    }
    fn drop_front(&mut self) {
        if let Some(p) = self.items.pop_front() {
            self.free.push(p.pixels);
        }
    }
}

/// Counts of what was read.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RecordingStats {
    /// Colour images read.
    pub color: u64,
    /// Depth images read.
    pub depth: u64,
    /// Calibration messages read.
    pub camera_info: u64,
    /// Frames delivered.
    pub frames: u64,
    /// Images dropped because no partner came within the tolerance.
    pub unpaired: u64,
}

/// Frames of one recording, in order.
pub struct RecordingReader {
    source: McapSource,
    topics: RecordingTopics,
    camera_override: Option<CameraModel>,
    camera: Option<CameraModel>,
    color: Queue<u8>,
    depth: Queue<u16>,
    frame_rgb: Vec<u8>,
    frame_depth: Vec<u16>,
    /// What a decoded image borrows (reused).
    holder: ImageHolder,
    stats: RecordingStats,
    damage: Option<Damage>,
}

impl std::fmt::Debug for RecordingReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordingReader").field("topics", &self.topics).field("stats", &self.stats).finish()
    }
}

#[derive(Debug, Clone, Copy)]
enum Role {
    Color,
    Depth,
    CameraInfo,
}

/// Checks that the chosen topics are among a recording's `channels` (topic, schema);
/// the calibration topic only if it is read (`needs_calibration`: no camera given).
fn check_topics(
    path: &Path,
    topics: &RecordingTopics,
    needs_calibration: bool,
    channels: &[(String, String)],
) -> Result<(), RecordingError> {
    let chosen = [
        ("colour", "color-topic", &topics.color, true),
        ("depth", "depth-topic", &topics.depth, true),
        ("calibration", "camera-info-topic", &topics.camera_info, needs_calibration),
    ];
    for (what, flag, topic, needed) in chosen {
        if needed && !channels.iter().any(|(t, _)| t == topic) {
            let mut available: Vec<String> = channels.iter().take(20).map(|(t, s)| format!("{t} ({s})")).collect();
            if channels.len() > 20 {
                available.push(format!("and {} more", channels.len() - 20));
            }
            let available = if available.is_empty() { "none".into() } else { available.join(", ") };
            return Err(RecordingError::NoSuchTopic {
                path: path.to_path_buf(),
                what,
                flag,
                topic: topic.clone(),
                available,
            });
        }
    }
    Ok(())
}

fn message_error(topic: &str, index: u64, reason: impl Into<String>) -> RecordingError {
    RecordingError::Message { topic: topic.to_string(), index, reason: reason.into() }
}

/// Images that are waiting longer than this many partners are dropped.
const MAX_WAITING: usize = 8;

impl RecordingReader {
    /// Opens a recording. With `camera`, its intrinsics replace the calibration topic.
    pub fn open(path: &Path, topics: RecordingTopics, camera: Option<CameraModel>) -> Result<Self, RecordingError> {
        let names = [topics.color.as_str(), topics.depth.as_str(), topics.camera_info.as_str()];
        let source = McapSource::open(path, &names).map_err(|source| match source {
            mcap::McapError::Io(source) => RecordingError::Unreadable { path: path.to_path_buf(), source },
            source => RecordingError::Open { path: path.to_path_buf(), source },
        })?;
        if let Some(channels) = source.channels() {
            check_topics(path, &topics, camera.is_none(), channels)?;
        }
        Ok(RecordingReader {
            source,
            topics,
            camera_override: camera,
            camera: None,
            color: Queue::new(),
            depth: Queue::new(),
            frame_rgb: Vec::new(),
            frame_depth: Vec::new(),
            holder: ImageHolder::default(),
            stats: RecordingStats::default(),
            damage: None,
        })
    }

    /// Whether the file is read through its index or streamed.
    pub fn mode(&self) -> ReadMode {
        self.source.mode()
    }

    /// The number of depth images, if the file's summary says (for progress).
    pub fn depth_count(&self) -> Option<u64> {
        self.source.message_count(&self.topics.depth)
    }

    /// What was read so far.
    pub fn stats(&self) -> RecordingStats {
        self.stats
    }

    /// Where the file was damaged, once the frames before the damage are delivered.
    pub fn damage(&self) -> Option<&Damage> {
        self.damage.as_ref()
    }

    /// Damaged chunks skipped in indexed reading (the frames in them are lost, the
    /// others read), with what was wrong.
    pub fn skipped_chunks(&self) -> &[String] {
        self.source.skipped_chunks()
    }

    /// The topics read.
    pub fn topics(&self) -> &RecordingTopics {
        &self.topics
    }

    /// The next frame, stamped with its depth image's stamp; `Ok(None)` at the end of the
    /// recording or at damage (see [`Self::damage`]).
    pub fn next_frame(&mut self) -> Result<Option<RgbdFrame<'_>>, RecordingError> {
        loop {
            if let Some((stamp_ns, camera, index)) = self.pair()? {
                return RgbdFrame::new(stamp_ns, camera, &self.frame_rgb, &self.frame_depth)
                    .map(Some)
                    .map_err(|e| message_error(&self.topics.depth, index, e.to_string()));
            }
            if !self.read_message()? {
                return Ok(None);
            }
        }
    }

    /// [`Self::next_frame`] into `out`, without copying: the frame's buffers are swapped
    /// with `out`'s, which the reader then reuses for later images. `Ok(false)` at the
    /// end of the recording or at damage.
    pub fn next_frame_into(&mut self, out: &mut OwnedFrame) -> Result<bool, RecordingError> {
        let Some(frame) = self.next_frame()? else { return Ok(false) };
        (out.stamp_ns, out.camera) = (frame.stamp_ns, Some(frame.camera));
        std::mem::swap(&mut out.rgb, &mut self.frame_rgb);
        std::mem::swap(&mut out.depth, &mut self.frame_depth);
        Ok(true)
    }

    /// Pairs the oldest waiting colour and depth images (nearest stamps, within the
    /// tolerance), dropping an image that has no partner. Moves a pair into the frame
    /// buffers and returns its stamp, camera and depth index.
    fn pair(&mut self) -> Result<Option<(u64, CameraModel, u64)>, RecordingError> {
        loop {
            let (Some(c), Some(d)) = (self.color.items.front(), self.depth.items.front()) else {
                return Ok(None);
            };
            let (tc, td) = (c.stamp_ns, d.stamp_ns);
            let closer =
                |next: Option<u64>, own: u64, other: u64| next.is_some_and(|n| n.abs_diff(other) < own.abs_diff(other));
            let color_superseded = closer(self.color.items.get(1).map(|p| p.stamp_ns), tc, td);
            let depth_superseded = closer(self.depth.items.get(1).map(|p| p.stamp_ns), td, tc);
            if tc.abs_diff(td) > PAIRING_TOLERANCE_NS || color_superseded || depth_superseded {
                if color_superseded || (!depth_superseded && tc < td) {
                    self.color.drop_front();
                } else {
                    self.depth.drop_front();
                }
                self.stats.unpaired += 1;
                continue;
            }
            let camera = self.camera_for(c, d)?;
            let index = d.index;
            if let (Some(c), Some(d)) = (self.color.items.pop_front(), self.depth.items.pop_front()) {
                self.color.free.push(std::mem::replace(&mut self.frame_rgb, c.pixels));
                self.depth.free.push(std::mem::replace(&mut self.frame_depth, d.pixels));
            }
            self.stats.frames += 1;
            return Ok(Some((td, camera, index)));
        }
    }

    /// The camera of a pair, after checking that the images and the calibration agree.
    fn camera_for(&self, c: &Pending<u8>, d: &Pending<u16>) -> Result<CameraModel, RecordingError> {
        if (c.width, c.height) != (d.width, d.height) {
            return Err(message_error(
                &self.topics.depth,
                d.index,
                format!(
                    "depth image is {}×{} but its colour image (message {} on {}) is {}×{}",
                    d.width, d.height, c.index, self.topics.color, c.width, c.height
                ),
            ));
        }
        let camera = match (self.camera_override, self.camera) {
            (Some(camera), _) | (None, Some(camera)) => camera,
            (None, None) => {
                return Err(RecordingError::NoCalibration {
                    topic: self.topics.color.clone(),
                    index: c.index,
                    camera_info_topic: self.topics.camera_info.clone(),
                });
            }
        };
        if (camera.width as usize, camera.height as usize) != (c.width, c.height) {
            let source = if self.camera_override.is_some() { "the given camera" } else { "the calibration" };
            return Err(message_error(
                &self.topics.color,
                c.index,
                format!(
                    "image is {}×{} but {source} ({}) is for {}×{}",
                    c.width, c.height, self.topics.camera_info, camera.width, camera.height
                ),
            ));
        }
        Ok(CameraModel { depth_scale_m: d.depth_scale_m, ..camera })
    }

    /// Reads and decodes one message of the chosen topics; `false` at the end or damage.
    /// The message is decoded while the source lends its bytes (no copy of them).
    fn read_message(&mut self) -> Result<bool, RecordingError> {
        let read = self.stats.color + self.stats.depth + self.stats.camera_info;
        let RecordingReader { source, topics, camera, color, depth, holder, stats, .. } = self;
        let mut sink = Sink { topics, camera, color, depth, holder, stats };
        match source.next_message_with(|message| sink.decode(message)) {
            None => Ok(false),
            Some(Err(e)) => {
                self.damage = Some(Damage { reason: e.to_string(), messages_before: read });
                Ok(false)
            }
            Some(Ok(decoded)) => decoded.map(|()| true),
        }
    }
}

/// Where a message's content goes: the calibration, or the queue of its images.
struct Sink<'a> {
    topics: &'a RecordingTopics,
    camera: &'a mut Option<CameraModel>,
    color: &'a mut Queue<u8>,
    depth: &'a mut Queue<u16>,
    holder: &'a mut ImageHolder,
    stats: &'a mut RecordingStats,
}

impl Sink<'_> {
    /// Decodes one message of the chosen topics (others are passed over).
    fn decode(&mut self, message: RawMessage<'_>) -> Result<(), RecordingError> {
        let topic = message.channel.topic.as_str();
        let (role, counter) = if topic == self.topics.color {
            (Role::Color, &mut self.stats.color)
        } else if topic == self.topics.depth {
            (Role::Depth, &mut self.stats.depth)
        } else if topic == self.topics.camera_info {
            (Role::CameraInfo, &mut self.stats.camera_info)
        } else {
            return Ok(());
        };
        let index = *counter;
        *counter += 1;
        let schema = message.channel.schema.as_ref().map(|s| s.name.as_str()).unwrap_or("");
        let encoding = message.channel.message_encoding.as_str();
        let kind = MessageKind::of(schema, encoding).ok_or_else(|| {
            message_error(
                topic,
                index,
                format!(
                    "schema '{schema}' in encoding '{encoding}' is not read (sensor_msgs/msg/Image, CompressedImage and CameraInfo in cdr, foxglove.RawImage, CompressedImage and CameraCalibration in protobuf are)"
                ),
            )
        })?;
        match role {
            Role::CameraInfo => {
                let camera = decode_calibration(kind, message.data).map_err(|e| message_error(topic, index, e))?;
                *self.camera = Some(camera);
            }
            Role::Color | Role::Depth => {
                let view = decode_image(kind, message.data, self.holder).map_err(|e| message_error(topic, index, e))?;
                let stamp_ns = if view.stamp_ns == 0 { message.log_time_ns } else { view.stamp_ns };
                let (width, height) = (view.width, view.height);
                let wanted_depth = matches!(role, Role::Depth);
                if view.format.is_depth() != wanted_depth {
                    let what = if wanted_depth { "a depth" } else { "a colour" };
                    return Err(message_error(topic, index, format!("{what} topic carries {:?} pixels", view.format)));
                }
                let dropped = if wanted_depth {
                    let mut pixels = self.depth.buffer();
                    let depth_scale_m = to_depth16(&view, &mut pixels);
                    push(self.depth, Pending { stamp_ns, index, width, height, depth_scale_m, pixels })
                } else {
                    let mut pixels = self.color.buffer();
                    to_rgb8(&view, &mut pixels);
                    push(self.color, Pending { stamp_ns, index, width, height, depth_scale_m: 0.0, pixels })
                };
                self.stats.unpaired += u64::from(dropped);
            }
        }
        Ok(())
    }
}

/// Queues an image, dropping the oldest when too many wait (a topic that stopped);
/// returns whether one was dropped.
fn push<T>(queue: &mut Queue<T>, item: Pending<T>) -> bool {
    let full = queue.items.len() >= MAX_WAITING;
    if full {
        queue.drop_front();
    }
    queue.items.push_back(item);
    full
}
