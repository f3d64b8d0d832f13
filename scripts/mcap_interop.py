#!/usr/bin/env python3
"""Reads what mrsmap writes with the independent Python readers (`mcap`, `mcap-ros2-support`,
`mcap-protobuf-support`) and checks it against the source data:

- RECORDING (from `mrsmap convert tum-to-mcap DATASET`): every colour, depth and CameraInfo
  message decodes; pixels equal the dataset's PNGs (depth 16UC1 in mm = TUM units / 5);
  K equals the camera file.
- POSES (from `mrsmap replay ... --out POSES --trajectory TRAJ`): every
  geometry_msgs/msg/PoseWithCovarianceStamped and foxglove.PosesInFrame decodes; the poses
  equal the TUM trajectory mrsmap wrote (which holds their inverses); covariances are
  symmetric positive definite; every /tf transform (tf2_msgs/msg/TFMessage) from the
  camera's optical frame to the object's frame equals the pose of its frame, and the model
  (sensor_msgs/msg/PointCloud2 in that frame, once) decodes into coloured points.

    python3 scripts/mcap_interop.py DATASET CAMERA.toml RECORDING POSES TRAJ
"""
import sys
import tomllib
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoder
from mcap_ros2.decoder import DecoderFactory as Ros2Decoder
from PIL import Image


def decoded(path):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[Ros2Decoder(), ProtobufDecoder()])
        return [(channel.topic, schema.name, msg) for schema, channel, _, msg in reader.iter_decoded_messages()]


def image_lists(dataset):
    """(stamp, file) of colour and depth images: associations.txt, or rgb.txt + depth.txt."""
    def rows(name):
        lines = (Path(dataset) / name).read_text().splitlines()
        return [l.split() for l in lines if l.strip() and not l.startswith("#")]
    if (Path(dataset) / "associations.txt").exists():
        a = rows("associations.txt")
        return [(r[0], r[1]) for r in a], [(r[2], r[3]) for r in a]
    return [tuple(r[:2]) for r in rows("rgb.txt")], [tuple(r[:2]) for r in rows("depth.txt")]


def check_recording(dataset, camera_file, recording):
    camera = tomllib.loads(Path(camera_file).read_text())
    messages = decoded(recording)
    by_topic = {}
    for topic, schema, msg in messages:
        by_topic.setdefault(topic, []).append((schema, msg))
    colour = by_topic["/camera/color/image_raw"]
    depth = by_topic["/camera/depth/image_raw"]
    info = by_topic["/camera/color/camera_info"]
    rgb_files, depth_files = image_lists(dataset)
    assert len(colour) == len(depth) == len(info) == len(depth_files), (len(colour), len(depth), len(info))
    for (schema, c), (_, d), (_, k), (_, rgb_file), (d_stamp, depth_file) in zip(
            colour, depth, info, rgb_files, depth_files):
        assert schema == "sensor_msgs/msg/Image" and c.encoding == "rgb8" and d.encoding == "16UC1"
        png_rgb = np.asarray(Image.open(Path(dataset) / rgb_file).convert("RGB"))
        got_rgb = np.frombuffer(bytes(c.data), np.uint8).reshape(c.height, c.width, 3)
        assert np.array_equal(png_rgb, got_rgb), "colour pixels differ"
        png_depth = np.asarray(Image.open(Path(dataset) / depth_file)).astype(np.float64)
        got_depth = np.frombuffer(bytes(d.data), "<u2").reshape(d.height, d.width)
        assert np.array_equal(np.round(png_depth * camera["depth_scale_m"] * 1000).astype(np.uint16), got_depth)
        stamp_ns = d.header.stamp.sec * 10**9 + d.header.stamp.nanosec
        assert abs(stamp_ns - round(float(d_stamp) * 1e9)) < 1000, (stamp_ns, d_stamp)
        assert list(k.k) == [camera["fx"], 0, camera["cx"], 0, camera["fy"], camera["cy"], 0, 0, 1], k.k
    print(f"recording: {len(colour)} colour, {len(depth)} depth, {len(info)} CameraInfo messages match the dataset")


def quat_matrix(x, y, z, w):
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def check_poses(poses, trajectory):
    messages = decoded(poses)
    ros = [(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, m) for t, s, m in messages
           if s == "geometry_msgs/msg/PoseWithCovarianceStamped"]
    fox = [m for t, s, m in messages if s == "foxglove.PosesInFrame"]
    rows = [list(map(float, l.split())) for l in Path(trajectory).read_text().splitlines()
            if l.strip() and not l.startswith("#")]
    assert len(ros) == len(rows) > 0 and len(fox) >= len(ros), (len(ros), len(rows), len(fox))
    for (stamp_ns, m), row, f in zip(ros, rows, fox):
        assert abs(stamp_ns * 1e-9 - row[0]) < 1e-6
        assert m.header.frame_id == "camera_color_optical_frame" == f.frame_id
        p, q = m.pose.pose.position, m.pose.pose.orientation
        rot = quat_matrix(q.x, q.y, q.z, q.w)
        t = np.array([p.x, p.y, p.z])
        # The trajectory holds object_from_camera = camera_from_object^-1.
        t_inv = -rot.T @ t
        assert np.allclose(t_inv, row[1:4], atol=2e-6), (t_inv, row[1:4])
        rot_traj = quat_matrix(*row[4:8])
        assert np.allclose(rot.T, rot_traj, atol=2e-6)
        cov = np.array(m.pose.covariance).reshape(6, 6)
        assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0), cov
        fp = f.poses[0]
        assert (fp.position.x, fp.position.y, fp.position.z) == (p.x, p.y, p.z)
        assert (fp.orientation.x, fp.orientation.w) == (q.x, q.w)
    print(f"poses: {len(ros)} PoseWithCovarianceStamped and {len(fox)} PosesInFrame messages match the trajectory")
    check_scene(messages, ros)


def check_scene(messages, ros):
    tf = [m for t, s, m in messages if t == "/tf" and s == "tf2_msgs/msg/TFMessage"]
    assert len(tf) == len(ros), (len(tf), len(ros))
    for (stamp_ns, pose), m in zip(ros, tf):
        (t,) = m.transforms
        assert (t.header.frame_id, t.child_frame_id) == ("camera_color_optical_frame", "mrsmap/teddy")
        assert t.header.stamp.sec * 10**9 + t.header.stamp.nanosec == stamp_ns
        p, q = pose.pose.pose.position, pose.pose.pose.orientation
        tr, rot = t.transform.translation, t.transform.rotation
        assert (tr.x, tr.y, tr.z, rot.x, rot.y, rot.z, rot.w) == (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
    (cloud,) = [m for t, s, m in messages if t == "/mrsmap/teddy/model" and s == "sensor_msgs/msg/PointCloud2"]
    assert cloud.header.frame_id == "mrsmap/teddy" and cloud.height == 1 and not cloud.is_bigendian
    fields = [(f.name, f.offset, f.datatype, f.count) for f in cloud.fields]
    assert fields == [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("rgb", 12, 7, 1)], fields
    points = np.frombuffer(bytes(cloud.data), np.dtype([("xyz", "<f4", 3), ("b", "u1"), ("g", "u1"), ("r", "u1"), ("a", "u1")]))
    assert len(points) == cloud.width > 1000 and cloud.row_step == 16 * cloud.width
    xyz = points["xyz"].astype(np.float64)
    assert np.all(np.isfinite(xyz)) and np.all(np.ptp(xyz, axis=0) < 1.0), np.ptp(xyz, axis=0)
    colour = np.stack([points["r"], points["g"], points["b"]], axis=1).astype(np.float64)
    assert np.mean(np.ptp(colour, axis=1) > 0) > 0.5 and np.all(points["a"] == 0)
    extent = np.ptp(xyz, axis=0) * 100
    print(f"scene: {len(tf)} /tf transforms match the poses; the model cloud holds {len(points)} coloured points "
          f"({extent[0]:.0f} x {extent[1]:.0f} x {extent[2]:.0f} cm) in frame {cloud.header.frame_id}")


if __name__ == "__main__":
    dataset, camera_file, recording, poses, trajectory = sys.argv[1:6]
    check_recording(dataset, camera_file, recording)
    check_poses(poses, trajectory)
