#!/usr/bin/env python3
"""An independent camera driver and pose reader in Python (iceoryx2 from PyPI), written
only from docs/wire-format.md: publishes the frames of a TUM clip to `mrsmap track` and
reads the poses back from the blackboard. With --detections it also plays a detector:
after frame 3 it sends the tracker a detection of the object 30 mm off its tracked pose
along the camera's x axis (mode "always"), from which frame 4 must be tracked back to
within 10 mm of frame 3's pose along x (between these frames the camera moves by up to
4 mm along x, 20 mm along y). Exits non-zero unless every frame is tracked (and the detection was undone).

    pip install iceoryx2==0.10.0 numpy pillow
    mrsmap track --config robot_config/tracker.toml &
    scripts/python_driver.py tests/data/fr3_teddy_8 --service mrsmap/camera0 --poses mrsmap/poses \
        --detections mrsmap/detections
"""
import argparse, ctypes, pathlib, sys, time

import iceoryx2 as iox2
import numpy as np
from PIL import Image

LAYOUT_VERSION = 2  # docs/wire-format.md


class FrameHeader(ctypes.Structure):
    _fields_ = [("layout_version", ctypes.c_uint32), ("width", ctypes.c_uint32),
                ("height", ctypes.c_uint32), ("reserved", ctypes.c_uint32),
                ("capture_stamp_ns", ctypes.c_uint64), ("send_stamp_ns", ctypes.c_uint64),
                ("sequence", ctypes.c_uint64), ("fx", ctypes.c_double), ("fy", ctypes.c_double),
                ("cx", ctypes.c_double), ("cy", ctypes.c_double),
                ("distortion", ctypes.c_double * 8), ("depth_scale_m", ctypes.c_double)]

    @staticmethod
    def type_name() -> str:
        return "MrsmapFrameHeader"


class RgbdFrameVga(ctypes.Structure):
    _fields_ = [("header", FrameHeader), ("rgb", ctypes.c_uint8 * (640 * 480 * 3)),
                ("depth", ctypes.c_uint16 * (640 * 480))]

    @staticmethod
    def type_name() -> str:
        return "MrsmapRgbdFrameVga"


class ObjectPose(ctypes.Structure):
    _fields_ = [("layout_version", ctypes.c_uint32), ("object_id", ctypes.c_uint32),
                ("frame_stamp_ns", ctypes.c_uint64), ("frame_sequence", ctypes.c_uint64),
                ("frame_send_stamp_ns", ctypes.c_uint64), ("publish_stamp_ns", ctypes.c_uint64),
                ("translation_m", ctypes.c_double * 3), ("rotation_xyzw", ctypes.c_double * 4),
                ("covariance", ctypes.c_double * 36), ("quality", ctypes.c_double),
                ("status", ctypes.c_uint32), ("bad_frames", ctypes.c_uint32),
                ("associations", ctypes.c_uint32), ("iterations", ctypes.c_uint32),
                ("build_ms", ctypes.c_float), ("register_ms", ctypes.c_float),
                ("total_ms", ctypes.c_float), ("free_space", ctypes.c_float),
                ("name", ctypes.c_uint8 * 32)]

    @staticmethod
    def type_name() -> str:
        return "MrsmapObjectPose"


class ObjectDetection(ctypes.Structure):
    _fields_ = [("layout_version", ctypes.c_uint32), ("mode", ctypes.c_uint32),
                ("frame_stamp_ns", ctypes.c_uint64), ("send_stamp_ns", ctypes.c_uint64),
                ("translation_m", ctypes.c_double * 3), ("rotation_xyzw", ctypes.c_double * 4),
                ("name", ctypes.c_uint8 * 32)]

    @staticmethod
    def type_name() -> str:
        return "MrsmapObjectDetection"


DETECTION_ALWAYS = 1  # docs/wire-format.md: 0 = when not tracking, 1 = always
DETECTED_AFTER_FRAME = 3
DETECTION_OFFSET_M = 0.03


def detector(node, service: str):
    name = iox2.ServiceName.new(service)
    svc = (node.service_builder(name).publish_subscribe(ObjectDetection)
           .enable_safe_overflow(True).subscriber_max_buffer_size(16)
           .subscriber_max_borrowed_samples(2).history_size(0)
           .max_publishers(8).max_subscribers(4).open_or_create())
    return svc.publisher_builder().create()


def frames(root: pathlib.Path):
    for line in (root / "associations.txt").read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        _, rgb, t_depth, depth = line.split()
        yield int(round(float(t_depth) * 1e9)), root / rgb, root / depth


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset", type=pathlib.Path)
    ap.add_argument("--service", default="mrsmap/camera0")
    ap.add_argument("--poses", default="mrsmap/poses")
    ap.add_argument("--detections", help="also send a detection on this service")
    args = ap.parse_args()
    assert ctypes.sizeof(FrameHeader) == 144 and ctypes.sizeof(ObjectPose) == 456
    assert ctypes.sizeof(ObjectDetection) == 112

    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    name = iox2.ServiceName.new(args.service + "/rgbd/vga")
    service = (node.service_builder(name).publish_subscribe(RgbdFrameVga)
               .enable_safe_overflow(True).subscriber_max_buffer_size(1)
               .subscriber_max_borrowed_samples(2).history_size(0)
               .max_publishers(2).max_subscribers(8).open_or_create())
    events = node.service_builder(name).event().max_notifiers(4).max_listeners(16).open_or_create()
    publisher = service.publisher_builder().create()
    notifier = events.notifier_builder().create()

    poses_name = iox2.ServiceName.new(args.poses)
    board = (node.service_builder(poses_name).blackboard_opener(ctypes.c_uint32)
             .max_readers(16).open())
    reader = board.reader_builder().create()
    entry = reader.entry(ctypes.c_uint32(0), ObjectPose)

    detections = detector(node, args.detections) if args.detections else None
    tracked = 0
    total = 0
    undone = None
    before = None
    for seq, (stamp, rgb_path, depth_path) in enumerate(frames(args.dataset)):
        rgb = np.asarray(Image.open(rgb_path).convert("RGB"), dtype=np.uint8)
        depth = np.asarray(Image.open(depth_path), dtype=np.uint16)
        sample = publisher.loan_uninit()
        f = ctypes.cast(sample.payload_ptr, ctypes.POINTER(RgbdFrameVga)).contents
        f.header = FrameHeader(LAYOUT_VERSION, 640, 480, 0, stamp, 0, seq,
                               535.4, 539.2, 320.1, 247.6, (ctypes.c_double * 8)(), 1 / 5000)
        np.ctypeslib.as_array(f.rgb)[:] = rgb.reshape(-1)
        np.ctypeslib.as_array(f.depth)[:] = depth.reshape(-1)
        f.header.send_stamp_ns = time.time_ns()  # as it is sent (docs/wire-format.md)
        sample.assume_init().send()
        notifier.notify()
        total += 1
        deadline = time.time() + 5
        while time.time() < deadline:
            pose = entry.get().decode_as(ObjectPose)
            if pose.frame_sequence == seq and pose.frame_send_stamp_ns != 0:
                break
            time.sleep(0.005)
        else:
            print(f"frame {seq}: no pose", file=sys.stderr)
            continue
        name = bytes(pose.name).split(b"\0")[0].decode()
        t = list(pose.translation_m)
        print(f"frame {seq}: {name} status {pose.status} quality {pose.quality:.2f} "
              f"free space {pose.free_space:.3f} camera_from_object t = [{t[0]:+.3f}, {t[1]:+.3f}, {t[2]:+.3f}]")
        # Estimated from this frame: status tracking and no bad frame (else a held pose).
        tracked += pose.status == 0 and pose.bad_frames == 0
        if detections is not None and seq == DETECTED_AFTER_FRAME:
            before = t
            shifted = (ctypes.c_double * 3)(t[0] + DETECTION_OFFSET_M, t[1], t[2])
            d = ObjectDetection(LAYOUT_VERSION, DETECTION_ALWAYS, stamp, time.time_ns(), shifted,
                                (ctypes.c_double * 4)(*pose.rotation_xyzw),
                                (ctypes.c_uint8 * 32)(*bytes(pose.name)))
            detections.send_copy(d)
            print(f"detection sent: {name} {DETECTION_OFFSET_M * 1e3:.0f} mm off its pose in frame {seq}")
        elif detections is not None and seq == DETECTED_AFTER_FRAME + 1:
            moved = t[0] - before[0]
            undone = abs(moved) < 0.010
            print(f"frame {seq}, tracked from the detection: {moved * 1e3:+.1f} mm along x from frame "
                  f"{seq - 1}'s pose (the detection was {DETECTION_OFFSET_M * 1e3:+.0f} mm)")
    print(f"{tracked}/{total} frames tracked")
    if detections is not None and not undone:
        print("the pose after the detection did not come back to the object", file=sys.stderr)
        return 1
    return 0 if tracked == total else 1


if __name__ == "__main__":
    sys.exit(main())
