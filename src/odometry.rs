//! Frame-to-frame RGB-D odometry (the paper's Table 1 setting): each frame's map is
//! registered to the previous frame's map and the poses are chained,
//! `world_from_current = world_from_previous · previous_from_current`.
//!
//! Two maps are kept and swapped, so a step allocates nothing. The caller times the two
//! halves of a step ([`Odometry::build`], [`Odometry::track`]) if it wishes; this module
//! has no clock.

use crate::frame::RgbdFrame;
use crate::geometry::Pose;
use crate::map::{BuildReport, MapBuilder, MapCapacity, MapError, MapParams, MapParamsError, SurfelMap};
use crate::registration::{Registration, RegistrationError, RegistrationParams, RegistrationWorkspace, register};

/// How odometry runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryParams {
    /// Map building.
    pub map: MapParams,
    /// Registration.
    pub registration: RegistrationParams,
    /// Start each registration from the previous frame-to-frame motion (constant
    /// velocity) instead of from identity.
    pub constant_velocity: bool,
}

impl Default for OdometryParams {
    fn default() -> Self {
        OdometryParams {
            // Frame maps are registered, never saved or fused: no colour scatter.
            map: MapParams { color_scatter: false, ..MapParams::default() },
            registration: RegistrationParams::default(),
            constant_velocity: true,
        }
    }
}

/// The outcome of registering one frame.
// Returned by value once per frame; boxing the large variant would allocate.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrackOutcome {
    /// The first frame: nothing to register to; the pose is the initial pose.
    First,
    /// Registered to the previous frame.
    Tracked(Registration),
    /// Registration failed; the pose is held at the previous frame's.
    Failed(RegistrationError),
}

/// Frame-to-frame odometry with preallocated maps.
#[derive(Debug)]
pub struct Odometry {
    params: OdometryParams,
    builder: MapBuilder,
    maps: [SurfelMap; 2],
    /// Index of the map of the newest frame.
    newest: usize,
    frames: usize,
    workspace: RegistrationWorkspace,
    world_from_camera: Pose,
    previous_from_current: Pose,
}

impl Odometry {
    /// Odometry for frames up to `max_width × max_height`, starting at `world_from_first`.
    pub fn new(
        params: OdometryParams,
        max_width: usize,
        max_height: usize,
        world_from_first: Pose,
    ) -> Result<Self, MapParamsError> {
        let capacity = MapCapacity::for_image(max_width * max_height);
        let maps = [SurfelMap::new(params.map, capacity)?, SurfelMap::new(params.map, capacity)?];
        Ok(Odometry {
            params,
            builder: MapBuilder::new(max_width, max_height, capacity.surfels),
            maps,
            newest: 1,
            frames: 0,
            workspace: RegistrationWorkspace::new(capacity.nodes),
            world_from_camera: world_from_first,
            previous_from_current: Pose::identity(),
        })
    }

    /// Starts over at `world_from_first`: the next frame is a first frame. Keeps the
    /// storage.
    pub fn reset(&mut self, world_from_first: Pose) {
        self.frames = 0;
        self.world_from_camera = world_from_first;
        self.previous_from_current = Pose::identity();
    }

    /// Builds the map of a new frame (the first half of a step).
    pub fn build(&mut self, frame: &RgbdFrame) -> Result<BuildReport, MapError> {
        let next = 1 - self.newest;
        let report = self.builder.build(frame, &mut self.maps[next])?;
        self.newest = next;
        self.frames += 1;
        Ok(report)
    }

    /// Registers the newest map to the previous one and chains the pose (the second
    /// half of a step).
    pub fn track(&mut self) -> TrackOutcome {
        if self.frames < 2 {
            return TrackOutcome::First;
        }
        let (current, previous) = (&self.maps[self.newest], &self.maps[1 - self.newest]);
        let guess = if self.params.constant_velocity { self.previous_from_current } else { Pose::identity() };
        match register(previous, current, &guess, &self.params.registration, &mut self.workspace) {
            Ok(reg) => {
                self.previous_from_current = reg.model_from_scene;
                self.world_from_camera *= reg.model_from_scene;
                TrackOutcome::Tracked(reg)
            }
            Err(e) => {
                self.previous_from_current = Pose::identity();
                TrackOutcome::Failed(e)
            }
        }
    }

    /// The pose of the newest frame.
    pub fn world_from_camera(&self) -> Pose {
        self.world_from_camera
    }

    /// The map of the newest frame.
    pub fn newest_map(&self) -> &SurfelMap {
        &self.maps[self.newest]
    }
}
