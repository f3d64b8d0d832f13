/* mrsmap_wire.h: the messages of mrsmap's tracker process for drivers, clients and
 * detectors written in C (C11) or C++ (C++17), against iceoryx2 0.10 (`ipc` services).
 *
 * The C twin of src/io/wire.rs (message types) and src/io/ipc.rs (service names and
 * settings); docs/wire-format.md says what every field means. tests/c_header.rs
 * compiles this file as C and as C++ and checks every size, alignment, offset and type
 * name against the Rust definitions, so the two cannot drift apart.
 *
 * iceoryx2 connects two ports only when their payload's type name, size and alignment
 * agree: in C++ the name is each struct's `IOX2_TYPE_NAME` (iceoryx2-cxx reads it); in C
 * pass the MRSMAP_*_TYPE_NAME string, sizeof and _Alignof to the service builder's payload
 * type details. The services' settings below must match too, or opening a service fails.
 *
 * Little-endian (x86-64, aarch64); every struct is laid out without implicit padding.
 * All stamps are nanoseconds since the Unix epoch (CLOCK_REALTIME).
 */
#ifndef MRSMAP_WIRE_H
#define MRSMAP_WIRE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
#define MRSMAP_WIRE_TYPE_NAME(name) static constexpr const char* IOX2_TYPE_NAME = name;
#define MRSMAP_WIRE_ASSERT(condition, message) static_assert(condition, message)
#else
#define MRSMAP_WIRE_TYPE_NAME(name)
#define MRSMAP_WIRE_ASSERT(condition, message) _Static_assert(condition, message)
#endif

/* Layout version of every message; a reader refuses other versions. */
#define MRSMAP_LAYOUT_VERSION 2u

/* ---- Services (src/io/ipc.rs) -------------------------------------------------------
 * Frames: publish-subscribe on "<camera>/rgbd/vga" or "<camera>/rgbd/qvga" (<camera> is
 * the tracker config's camera.service, default "mrsmap/camera0"), plus an event service
 * of the same name: the driver notifies after every send. */
#define MRSMAP_DEFAULT_CAMERA_SERVICE "mrsmap/camera0"
#define MRSMAP_VGA_SUFFIX "/rgbd/vga"
#define MRSMAP_QVGA_SUFFIX "/rgbd/qvga"
#define MRSMAP_FRAME_SAFE_OVERFLOW 1 /* on: the newest frame overwrites a stale one */
#define MRSMAP_FRAME_SUBSCRIBER_MAX_BUFFER_SIZE 1
#define MRSMAP_FRAME_SUBSCRIBER_MAX_BORROWED_SAMPLES 2
#define MRSMAP_FRAME_HISTORY_SIZE 0
#define MRSMAP_FRAME_MAX_PUBLISHERS 2
#define MRSMAP_FRAME_MAX_SUBSCRIBERS 8
/* Every event service (frames, poses). */
#define MRSMAP_EVENT_MAX_NOTIFIERS 4
#define MRSMAP_EVENT_MAX_LISTENERS 16
/* Poses: a blackboard with uint32_t keys (the object id) and MrsmapObjectPose values,
 * created by the tracker, plus an event service of the same name that the tracker
 * notifies after each frame's poses. */
#define MRSMAP_POSES_SERVICE "mrsmap/poses"
#define MRSMAP_POSES_MAX_READERS 16
#define MRSMAP_MAX_OBJECTS 64
/* Detections: publish-subscribe, no event (a frame wakes the tracker). */
#define MRSMAP_DETECTIONS_SERVICE "mrsmap/detections"
#define MRSMAP_DETECTION_SAFE_OVERFLOW 1
#define MRSMAP_DETECTION_SUBSCRIBER_MAX_BUFFER_SIZE 16
#define MRSMAP_DETECTION_SUBSCRIBER_MAX_BORROWED_SAMPLES 2
#define MRSMAP_DETECTION_HISTORY_SIZE 0
#define MRSMAP_DETECTION_MAX_PUBLISHERS 8
#define MRSMAP_DETECTION_MAX_SUBSCRIBERS 4

/* ---- Payload type names (what iceoryx2 compares) ------------------------------------ */
#define MRSMAP_FRAME_HEADER_TYPE_NAME "MrsmapFrameHeader"
#define MRSMAP_RGBD_FRAME_VGA_TYPE_NAME "MrsmapRgbdFrameVga"
#define MRSMAP_RGBD_FRAME_QVGA_TYPE_NAME "MrsmapRgbdFrameQvga"
#define MRSMAP_OBJECT_POSE_TYPE_NAME "MrsmapObjectPose"
#define MRSMAP_OBJECT_DETECTION_TYPE_NAME "MrsmapObjectDetection"

/* ---- Frames ------------------------------------------------------------------------- */

/* What precedes the pixels of a frame (144 bytes). */
typedef struct MrsmapFrameHeader {
    uint32_t layout_version;   /* MRSMAP_LAYOUT_VERSION */
    uint32_t width;            /* 640 (VGA) or 320 (QVGA) */
    uint32_t height;           /* 480 or 240 */
    uint32_t reserved;         /* 0 */
    uint64_t capture_stamp_ns; /* when the images were taken (the depth image's stamp) */
    uint64_t send_stamp_ns;    /* set just before send, once the pixels are in the sample */
    uint64_t sequence;         /* the driver's frame counter (restarts with the driver) */
    double fx, fy, cx, cy;     /* pinhole intrinsics of the depth pixels (px) */
    double distortion[8];      /* OpenCV order k1 k2 p1 p2 k3 k4 k5 k6; zeros: rectified */
    double depth_scale_m;      /* metres per depth unit (1/5000 TUM, 1/1000 OpenNI) */
    MRSMAP_WIRE_TYPE_NAME(MRSMAP_FRAME_HEADER_TYPE_NAME)
} MrsmapFrameHeader;

/* A VGA frame: the header, row-major RGB8 registered to the depth image, then row-major
 * depth (0 = no measurement). Write it in place into a loaned sample. */
typedef struct MrsmapRgbdFrameVga {
    MrsmapFrameHeader header;
    uint8_t rgb[640 * 480 * 3];
    uint16_t depth[640 * 480];
    MRSMAP_WIRE_TYPE_NAME(MRSMAP_RGBD_FRAME_VGA_TYPE_NAME)
} MrsmapRgbdFrameVga;

/* A QVGA frame (320×240), laid out as the VGA one. */
typedef struct MrsmapRgbdFrameQvga {
    MrsmapFrameHeader header;
    uint8_t rgb[320 * 240 * 3];
    uint16_t depth[320 * 240];
    MRSMAP_WIRE_TYPE_NAME(MRSMAP_RGBD_FRAME_QVGA_TYPE_NAME)
} MrsmapRgbdFrameQvga;

/* ---- Poses (tracker -> control stack) ----------------------------------------------- */

/* MrsmapObjectPose.status */
#define MRSMAP_STATUS_TRACKING 0u      /* bad_frames 0: estimated from this frame; > 0: held */
#define MRSMAP_STATUS_LOST 1u          /* pose = last good one */
#define MRSMAP_STATUS_INITIALISING 2u  /* pose = the hypothesis tried */
#define MRSMAP_STATUS_INVALID_FRAME 3u /* the frame could not be used */

/* One object's pose for one frame (456 bytes). */
typedef struct MrsmapObjectPose {
    uint32_t layout_version;      /* MRSMAP_LAYOUT_VERSION */
    uint32_t object_id;           /* index in the tracker config (the blackboard key) */
    uint64_t frame_stamp_ns;      /* capture stamp of the frame answered */
    uint64_t frame_sequence;      /* its sequence number */
    uint64_t frame_send_stamp_ns; /* when the driver sent it (0 before the first frame) */
    uint64_t publish_stamp_ns;    /* when the tracker wrote this pose */
    double translation_m[3];      /* camera_from_object, camera optical frame (REP 103) */
    double rotation_xyzw[4];      /* camera_from_object, unit quaternion x y z w */
    double covariance[36];        /* row-major 6x6, ROS order: x y z, rot x y z */
    double quality;               /* ~1 good, < 0.5 failed (with free_space) */
    uint32_t status;              /* MRSMAP_STATUS_* */
    uint32_t bad_frames;          /* consecutive frames without a good registration */
    uint32_t associations;        /* surfel associations at the estimate */
    uint32_t iterations;          /* LM + Newton iterations */
    float build_ms;               /* building the object's scene map */
    float register_ms;            /* registration, quality and free space */
    float total_ms;               /* frame received -> poses written */
    float free_space;             /* share of the facing model surfels seen through */
    uint8_t name[32];             /* object name, UTF-8, NUL-padded */
    MRSMAP_WIRE_TYPE_NAME(MRSMAP_OBJECT_POSE_TYPE_NAME)
} MrsmapObjectPose;

/* ---- Detections (detector -> tracker) ----------------------------------------------- */

/* MrsmapObjectDetection.mode */
#define MRSMAP_DETECTION_WHEN_NOT_TRACKING 0u /* only to a lost or initialising object */
#define MRSMAP_DETECTION_ALWAYS 1u            /* also restart an object being tracked */

/* Where an external detector saw an object (112 bytes). */
typedef struct MrsmapObjectDetection {
    uint32_t layout_version; /* MRSMAP_LAYOUT_VERSION */
    uint32_t mode;           /* MRSMAP_DETECTION_* */
    uint64_t frame_stamp_ns; /* capture_stamp_ns of the frame looked at; 0: no stamp */
    uint64_t send_stamp_ns;  /* when the detector sent it */
    double translation_m[3]; /* camera_from_object, camera optical frame (REP 103) */
    double rotation_xyzw[4]; /* unit quaternion x y z w (norm within 1e-3 of 1) */
    uint8_t name[32];        /* the object's name in the tracker config, NUL-padded */
    MRSMAP_WIRE_TYPE_NAME(MRSMAP_OBJECT_DETECTION_TYPE_NAME)
} MrsmapObjectDetection;

/* ---- The layout, checked where this header is compiled ------------------------------ */
MRSMAP_WIRE_ASSERT(sizeof(MrsmapFrameHeader) == 144, "MrsmapFrameHeader is 144 bytes");
MRSMAP_WIRE_ASSERT(offsetof(MrsmapFrameHeader, fx) == 40, "MrsmapFrameHeader.fx at 40");
MRSMAP_WIRE_ASSERT(offsetof(MrsmapFrameHeader, depth_scale_m) == 136, "depth_scale_m at 136");
MRSMAP_WIRE_ASSERT(sizeof(MrsmapRgbdFrameVga) == 144 + 640 * 480 * 5, "VGA frame size");
MRSMAP_WIRE_ASSERT(offsetof(MrsmapRgbdFrameVga, depth) == 144 + 640 * 480 * 3, "VGA depth");
MRSMAP_WIRE_ASSERT(sizeof(MrsmapRgbdFrameQvga) == 144 + 320 * 240 * 5, "QVGA frame size");
MRSMAP_WIRE_ASSERT(offsetof(MrsmapRgbdFrameQvga, depth) == 144 + 320 * 240 * 3, "QVGA depth");
MRSMAP_WIRE_ASSERT(sizeof(MrsmapObjectPose) == 456, "MrsmapObjectPose is 456 bytes");
MRSMAP_WIRE_ASSERT(offsetof(MrsmapObjectPose, quality) == 384, "MrsmapObjectPose.quality");
MRSMAP_WIRE_ASSERT(offsetof(MrsmapObjectPose, name) == 424, "MrsmapObjectPose.name at 424");
MRSMAP_WIRE_ASSERT(sizeof(MrsmapObjectDetection) == 112, "MrsmapObjectDetection is 112 bytes");
MRSMAP_WIRE_ASSERT(offsetof(MrsmapObjectDetection, name) == 80, "MrsmapObjectDetection.name");

#endif /* MRSMAP_WIRE_H */
