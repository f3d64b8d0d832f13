//! The iceoryx2 services every process opens, with one definition of their names and
//! quality of service (iceoryx2 refuses to connect processes whose QoS differ).
//!
//! | service | payload | QoS |
//! |---|---|---|
//! | `<camera>/rgbd/vga`, `<camera>/rgbd/qvga` | [`RgbdFrameVga`](super::wire::RgbdFrameVga) / [`RgbdFrameQvga`](super::wire::RgbdFrameQvga) | safe overflow, subscriber buffer 1 (a late subscriber gets the newest frame, stale ones are overwritten, the driver is never blocked), history 0, ≤ 2 publishers, ≤ 8 subscribers |
//! | same name, event | — | the driver notifies after each send; subscribers wait on it (no polling) |
//! | `mrsmap/poses` | blackboard, key `u32` object id → [`ObjectPose`] | created by the tracker (its only writer; a restarted tracker reopens the one its clients kept), ≤ 16 readers; each entry holds the object's newest pose |
//! | `mrsmap/poses`, event | — | the tracker notifies after each frame's poses |
//! | `mrsmap/detections` | [`ObjectDetection`] | safe overflow, subscriber buffer 16 (the oldest is dropped when more arrive between two frames), history 0, ≤ 8 publishers (detectors), ≤ 4 subscribers (trackers); no event: the tracker takes them before each frame |
//!
//! Poses go on a blackboard rather than a publish–subscribe service: updating an entry
//! writes shared memory in place, while iceoryx2 0.10's publisher allocates a small
//! shared-state block on the heap for every loaned sample (measured), and the tracker
//! loop allocates nothing. A control stack wants the newest pose anyway; the frame
//! sequence in each pose shows whether one was missed.

use super::wire::{ObjectDetection, ObjectPose, WireFrame};
use iceoryx2::node::Node;
use iceoryx2::port::writer::EntryHandleMutError;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::blackboard::{BlackboardCreateError, BlackboardOpenError};
use iceoryx2::service::builder::publish_subscribe as publish_subscribe_builder;
use iceoryx2::service::port_factory::{blackboard, event, publish_subscribe};

/// The iceoryx2 service flavour of every port: inter-process shared memory.
pub type Ipc = iceoryx2::service::ipc::Service;

/// The camera driver's default service prefix (`mrsmap camera --service`).
pub const DEFAULT_CAMERA_SERVICE: &str = "mrsmap/camera0";

/// The default pose service.
pub const POSES_SERVICE: &str = "mrsmap/poses";

/// The default detection service.
pub const DETECTIONS_SERVICE: &str = "mrsmap/detections";

/// The settings of a publish–subscribe service: every process opens it with these
/// (src/io/mrsmap_wire.h has them for C and C++ programs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PubSubQos {
    /// A full subscriber buffer drops its oldest sample instead of blocking the sender.
    pub safe_overflow: bool,
    /// Samples a subscriber holds until it takes them.
    pub subscriber_max_buffer_size: usize,
    /// Samples a subscriber may hold borrowed at once.
    pub subscriber_max_borrowed_samples: usize,
    /// Samples a late subscriber receives on connecting.
    pub history_size: usize,
    /// Most publishers.
    pub max_publishers: usize,
    /// Most subscribers.
    pub max_subscribers: usize,
}

impl PubSubQos {
    /// `builder` with these settings.
    fn apply<P: std::fmt::Debug + ZeroCopySend>(
        &self,
        builder: publish_subscribe_builder::Builder<P, (), Ipc>,
    ) -> publish_subscribe_builder::Builder<P, (), Ipc> {
        builder
            .enable_safe_overflow(self.safe_overflow)
            .subscriber_max_buffer_size(self.subscriber_max_buffer_size)
            .subscriber_max_borrowed_samples(self.subscriber_max_borrowed_samples)
            .history_size(self.history_size)
            .max_publishers(self.max_publishers)
            .max_subscribers(self.max_subscribers)
    }
}

/// The frame services: a buffer of one with safe overflow, so a subscriber always takes
/// the newest frame and the driver is never blocked.
pub const FRAME_QOS: PubSubQos = PubSubQos {
    safe_overflow: true,
    subscriber_max_buffer_size: 1,
    subscriber_max_borrowed_samples: 2,
    history_size: 0,
    max_publishers: 2,
    max_subscribers: 8,
};

/// The detection service: the tracker's subscriber holds up to 16 detections between
/// two frames (the oldest is dropped when more arrive).
pub const DETECTION_QOS: PubSubQos = PubSubQos {
    safe_overflow: true,
    subscriber_max_buffer_size: 16,
    subscriber_max_borrowed_samples: 2,
    history_size: 0,
    max_publishers: 8,
    max_subscribers: 4,
};

/// Most notifiers of every event service (frames, poses).
pub const EVENT_MAX_NOTIFIERS: usize = 4;

/// Most listeners of every event service.
pub const EVENT_MAX_LISTENERS: usize = 16;

/// Most readers of the pose blackboard.
pub const POSES_MAX_READERS: usize = 16;

/// An iceoryx2 operation failed.
#[derive(Debug, thiserror::Error)]
#[error("iceoryx2: {what}: {message}")]
pub struct IpcError {
    /// What was being done (names the service).
    pub what: String,
    /// iceoryx2's error.
    pub message: String,
}

impl IpcError {
    /// An error while doing `what`; iceoryx2's errors that a user can act on get a hint
    /// of what to do ([`hint`]).
    pub fn new(what: impl Into<String>, error: impl std::fmt::Debug) -> Self {
        let message = format!("{error:?}");
        let message = match hint(&message) {
            Some(hint) => format!("{message} ({hint})"),
            None => message,
        };
        IpcError { what: what.into(), message }
    }
}

/// What to do about an iceoryx2 error, from the name of its variant (`message` is its
/// `Debug` form, e.g. `PublishSubscribeOpenError(IncompatibleTypes)`).
pub fn hint(message: &str) -> Option<&'static str> {
    const HINTS: [(&str, &str); 9] = [
        (
            "ExceedsMaxSupportedPublishers",
            "the service has all the publishers it allows, 2 camera drivers on a frame service or 8 detectors \
             on the detection service: stop one of the others",
        ),
        (
            "ExceedsMaxSupportedSubscribers",
            "the service has all the subscribers it allows, 8 on a frame service or 4 trackers on the \
             detection service: stop one of the others",
        ),
        ("ExceedsMaxSupportedReaders", "the pose service has all the 16 readers it allows: stop one of the clients"),
        ("ExceedsMaxSupportedNotifiers", "the event service has all the 4 notifiers it allows: stop one of them"),
        ("ExceedsMaxSupportedListeners", "the event service has all the 16 listeners it allows: stop one of them"),
        (
            "IncompatibleTypes",
            "the service exists with another message type or size: a process built for another layout version \
             (docs/wire-format.md)",
        ),
        (
            "IncompatibleMessagingPattern",
            "a service of this name exists for another messaging pattern: another program uses the name",
        ),
        (
            "DoesNotSupportRequested",
            "the service exists with other settings: every process must open it with those of \
             docs/wire-format.md",
        ),
        ("IncompatibleOverflowBehavior", "the service exists without safe overflow: see docs/wire-format.md"),
    ];
    HINTS.iter().find(|(needle, _)| message.contains(needle)).map(|(_, hint)| *hint)
}

/// The image sizes on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameSize {
    /// 640×480.
    Vga,
    /// 320×240.
    Qvga,
}

impl FrameSize {
    /// The frame service of camera `camera` at this size: the camera's prefix and
    /// [`Self::suffix`].
    pub fn service(&self, camera: &str) -> String {
        format!("{camera}{}", self.suffix())
    }

    /// What follows the camera's prefix in the name of its frame service at this size.
    pub fn suffix(&self) -> &'static str {
        match self {
            FrameSize::Vga => "/rgbd/vga",
            FrameSize::Qvga => "/rgbd/qvga",
        }
    }

    /// The other size.
    pub fn other(&self) -> FrameSize {
        match self {
            FrameSize::Vga => FrameSize::Qvga,
            FrameSize::Qvga => FrameSize::Vga,
        }
    }

    /// Width and height.
    pub fn dimensions(&self) -> (u32, u32) {
        match self {
            FrameSize::Vga => (640, 480),
            FrameSize::Qvga => (320, 240),
        }
    }
}

/// A process's iceoryx2 node, named for diagnostics. SIGINT and SIGTERM are turned into
/// termination requests that `Node::wait` and `WaitSet` report. iceoryx2 logs errors
/// only, unless `IOX2_LOG_LEVEL` says otherwise.
pub fn node(name: &str) -> Result<Node<Ipc>, IpcError> {
    // iceoryx2 warns on stderr that no iceoryx2.toml was found; its defaults are ours.
    set_log_level_from_env_or(LogLevel::Error);
    let node_name = NodeName::new(name).map_err(|e| IpcError::new(format!("node name {name}"), e))?;
    NodeBuilder::new()
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<Ipc>()
        .map_err(|e| {
            let mut error = IpcError::new(format!("creating node {name}"), e);
            let global = &Config::global_config().global;
            let root = global.root_path().to_string();
            let folders = [root.clone(), global.node_dir().to_string(), global.service_dir().to_string()];
            if let Some(why) = folders.iter().find_map(|f| runtime_folder_problem(std::path::Path::new(f), &root)) {
                error.message = format!("{} ({why})", error.message);
            }
            error
        })
}

/// Why this process cannot use `folder`, one of iceoryx2's runtime folders under `root`,
/// if it cannot. iceoryx2 0.10 creates its folders for their creator's user and group
/// alone, and a process of another user then fails to create a node with nothing but
/// `InternalError`: after a camera driver run as root once, or with the driver and the
/// tracker run as two users.
fn runtime_folder_problem(folder: &std::path::Path, root: &str) -> Option<String> {
    use std::os::unix::fs::MetadataExt;
    let denied = std::fs::read_dir(folder).err()?.kind() == std::io::ErrorKind::PermissionDenied;
    let meta = std::fs::metadata(folder).ok().filter(|_| denied)?;
    let this_user = std::fs::metadata("/proc/self").map(|m| m.uid().to_string()).unwrap_or_else(|_| "?".into());
    Some(format!(
        "iceoryx2's folder {} belongs to user {} (mode {:o}), and this process's user {this_user} cannot use it: \
         run the camera driver, the tracker and its clients as one user; what another user left (a run as \
         root) must go first: stop every process that uses iceoryx2, then remove {root} and /dev/shm/iox2_*",
        folder.display(),
        meta.uid(),
        meta.mode() & 0o7777,
    ))
}

fn service_name(name: &str) -> Result<ServiceName, IpcError> {
    ServiceName::new(name).map_err(|e| IpcError::new(format!("service name {name}"), e))
}

/// Whether `name` is a valid iceoryx2 service name (a process that waits for a service
/// checks first, rather than waiting for one that cannot exist).
pub fn check_service_name(name: &str) -> Result<(), IpcError> {
    service_name(name).map(|_| ())
}

/// The frame service `name` (publish–subscribe with the QoS above).
pub fn frames<F: WireFrame>(
    node: &Node<Ipc>,
    name: &str,
) -> Result<publish_subscribe::PortFactory<Ipc, F, ()>, IpcError> {
    FRAME_QOS
        .apply(node.service_builder(&service_name(name)?).publish_subscribe::<F>())
        .open_or_create()
        .map_err(|e| IpcError::new(format!("opening frame service {name}"), e))
}

/// Whether a frame service `name` exists (some process, such as a camera driver, holds
/// it). For diagnostics only; an error counts as no.
pub fn frame_service_exists(name: &str) -> bool {
    service_name(name).is_ok_and(|n| {
        Ipc::does_exist(&n, Config::global_config(), MessagingPattern::PublishSubscribe).unwrap_or(false)
    })
}

/// The detection service `name` (publish–subscribe with the QoS above): detectors
/// publish, the tracker subscribes.
pub fn detections(
    node: &Node<Ipc>,
    name: &str,
) -> Result<publish_subscribe::PortFactory<Ipc, ObjectDetection, ()>, IpcError> {
    DETECTION_QOS
        .apply(node.service_builder(&service_name(name)?).publish_subscribe::<ObjectDetection>())
        .open_or_create()
        .map_err(|e| IpcError::new(format!("opening detection service {name}"), e))
}

/// The event service `name` that accompanies a publish–subscribe service.
pub fn events(node: &Node<Ipc>, name: &str) -> Result<event::PortFactory<Ipc>, IpcError> {
    node.service_builder(&service_name(name)?)
        .event()
        .max_notifiers(EVENT_MAX_NOTIFIERS)
        .max_listeners(EVENT_MAX_LISTENERS)
        .open_or_create()
        .map_err(|e| IpcError::new(format!("opening event service {name}"), e))
}

/// Most objects a pose blackboard holds (keys `0..`).
pub const MAX_OBJECTS: u32 = 64;

/// The pose blackboard's ports as the tracker holds them (dropped in this order).
pub struct PosePorts {
    /// One entry per object, key = object id, holding its newest pose.
    pub entries: Vec<PoseEntry>,
    /// The blackboard's only writer.
    pub writer: PoseWriter,
    /// The blackboard.
    pub service: PoseBlackboard,
}

/// The pose blackboard (key = object id).
pub type PoseBlackboard = blackboard::PortFactory<Ipc, u32>;

/// The tracker's writer of the pose blackboard.
pub type PoseWriter = iceoryx2::port::writer::Writer<Ipc, u32>;

/// One object's entry in the pose blackboard, as its writer holds it.
pub type PoseEntry = iceoryx2::port::writer::EntryHandleMut<Ipc, u32, ObjectPose>;

/// Creates the pose blackboard `name` (by default [`POSES_SERVICE`]) with one entry per
/// object of `initial` (key = object id) and becomes its writer. Clients open it.
///
/// A blackboard lives as long as any process holds it, so after a tracker stopped its
/// clients may still keep it. One whose tracker exited is opened again, its entries set
/// to `initial` (no client reads the earlier tracker's last poses as new), and the
/// clients keep reading without a restart. A kept blackboard that cannot be used (the
/// entries of a tracker that crashed stay claimed in iceoryx2 0.10 until the blackboard
/// goes; one of a tracker with fewer objects lacks entries) gives [`PosesKept`]: the
/// caller waits for the clients to let go (`mrsmap poses` does once no tracker writes)
/// and tries again. Refused when another tracker writes there.
pub fn publish_poses(
    node: &Node<Ipc>,
    name: &str,
    initial: &[ObjectPose],
) -> Result<Result<PosePorts, PosesKept>, IpcError> {
    if initial.len() > MAX_OBJECTS as usize {
        return Err(IpcError::new(format!("pose blackboard {name}"), format!("more than {MAX_OBJECTS} objects")));
    }
    let service = create_or_open_poses(node, name, initial)?;
    let writer = service.writer_builder().create().map_err(|e| {
        let what = format!(
            "writing poses on {name} (another tracker publishes there: stop it, or choose another [poses] service)"
        );
        IpcError::new(what, e)
    })?;
    let mut entries = Vec::with_capacity(initial.len());
    for (k, pose) in initial.iter().enumerate() {
        match writer.entry::<ObjectPose>(&(k as u32)) {
            Ok(entry) => {
                entry.update_with_copy(*pose);
                entries.push(entry);
            }
            Err(EntryHandleMutError::HandleAlreadyExists) => return Ok(Err(PosesKept::OfCrashedTracker)),
            Err(EntryHandleMutError::EntryDoesNotExist) => return Ok(Err(PosesKept::WithFewerObjects)),
        }
    }
    Ok(Ok(PosePorts { entries, writer, service }))
}

/// How long [`create_or_open_poses`] retries a blackboard that is being removed.
const BLACKBOARD_REMOVAL_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(2);

/// Creates the pose blackboard `name` with the entries `initial`, or opens it where it
/// exists. Its last client can let go between the two: iceoryx2 then removes it, its
/// data segments before its name, and the opening finds it half gone
/// (`ServiceInCorruptedState`, `IsMarkedForDestruction`, `DoesNotExist`; a creation at
/// that moment can fail likewise). Both are tried again until the removal is over; a
/// blackboard still in such a state after [`BLACKBOARD_REMOVAL_TIMEOUT`] is an error.
fn create_or_open_poses(node: &Node<Ipc>, name: &str, initial: &[ObjectPose]) -> Result<PoseBlackboard, IpcError> {
    let started = std::time::Instant::now();
    let service_name = service_name(name)?;
    let retry = || {
        std::thread::sleep(std::time::Duration::from_millis(1));
        started.elapsed() < BLACKBOARD_REMOVAL_TIMEOUT
    };
    loop {
        let mut builder =
            node.service_builder(&service_name).blackboard_creator::<u32>().max_readers(POSES_MAX_READERS);
        for (k, pose) in initial.iter().enumerate() {
            builder = builder.add::<ObjectPose>(k as u32, *pose);
        }
        match builder.create() {
            Ok(service) => return Ok(service),
            Err(BlackboardCreateError::AlreadyExists) => {}
            Err(
                BlackboardCreateError::ServiceInCorruptedState | BlackboardCreateError::IsBeingCreatedByAnotherInstance,
            ) if retry() => continue,
            Err(e) => return Err(IpcError::new(format!("creating pose blackboard {name}"), e)),
        }
        match open_blackboard(node, &service_name) {
            Ok(service) => return Ok(service),
            Err(
                BlackboardOpenError::ServiceInCorruptedState
                | BlackboardOpenError::IsMarkedForDestruction
                | BlackboardOpenError::DoesNotExist,
            ) if retry() => {}
            Err(e) => return Err(IpcError::new(format!("opening pose blackboard {name}"), e)),
        }
    }
}

fn open_blackboard(node: &Node<Ipc>, name: &ServiceName) -> Result<PoseBlackboard, BlackboardOpenError> {
    node.service_builder(name).blackboard_opener::<u32>().max_readers(POSES_MAX_READERS).open()
}

/// Why the pose blackboard that clients keep from an earlier tracker cannot be written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PosesKept {
    /// That tracker crashed: its entries stay claimed while the blackboard exists.
    #[error("it holds the entries of a tracker that crashed")]
    OfCrashedTracker,
    /// That tracker had fewer objects.
    #[error("it was made by a tracker with fewer objects")]
    WithFewerObjects,
}

/// Opens the pose blackboard `name`.
pub fn open_poses(node: &Node<Ipc>, name: &str) -> Result<PoseBlackboard, IpcError> {
    open_blackboard(node, &service_name(name)?).map_err(|e| IpcError::new(format!("opening pose blackboard {name}"), e))
}

/// Nanoseconds since the Unix epoch (the stamps in the wire messages).
pub fn now_ns() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use iceoryx2::service::builder::publish_subscribe::{
        PublishSubscribeOpenError as Open, PublishSubscribeOpenOrCreateError as OpenOrCreate,
    };

    #[test]
    fn errors_a_user_can_act_on_get_a_hint_and_others_none() {
        let nested =
            IpcError::new("opening frame service x", OpenOrCreate::PublishSubscribeOpenError(Open::IncompatibleTypes));
        assert!(
            nested.to_string().starts_with(
                "iceoryx2: opening frame service x: PublishSubscribeOpenError(IncompatibleTypes) (the service exists \
                 with another message type"
            ),
            "{nested}"
        );
        let settings = IpcError::new("x", Open::DoesNotSupportRequestedAmountOfPublishers);
        assert!(settings.message.contains("docs/wire-format.md"), "{settings}");
        assert_eq!(IpcError::new("x", Open::InternalFailure).message, "InternalFailure");
    }

    #[test]
    fn the_hints_give_the_limits_the_services_have() {
        let says = |error: &str, limits: &[usize]| {
            let h = hint(error).expect("a hint");
            for n in limits {
                assert!(h.contains(&format!("{n} ")), "{error}: {h} lacks {n}");
            }
        };
        says("ExceedsMaxSupportedPublishers", &[FRAME_QOS.max_publishers, DETECTION_QOS.max_publishers]);
        says("ExceedsMaxSupportedSubscribers", &[FRAME_QOS.max_subscribers, DETECTION_QOS.max_subscribers]);
        says("ExceedsMaxSupportedReaders", &[POSES_MAX_READERS]);
        says("ExceedsMaxSupportedNotifiers", &[EVENT_MAX_NOTIFIERS]);
        says("ExceedsMaxSupportedListeners", &[EVENT_MAX_LISTENERS]);
    }
}
