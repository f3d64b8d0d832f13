#!/usr/bin/env python3
"""Writes frames of a TUM RGB-D sequence as a compressed ROS 2 recording, the way a robot
records to save bandwidth, with the Python `mcap-ros2-support` writer (independent of
mrsmap): sensor_msgs/msg/CompressedImage JPEG colour ("rgb8; jpeg compressed bgr8") on
/camera/color/image_raw/compressed, image_transport's compressedDepth ("16UC1;
compressedDepth png", mm) on /camera/depth/image_raw/compressedDepth, and CameraInfo.

    python3 -m pip install 'mcap==1.6.0' 'mcap-ros2-support==0.6.0' 'pillow==13.0.0'
    python3 scripts/tum_to_compressed_mcap.py DATASET_DIR OUT.mcap --first-frame 100 --quality 90
    mrsmap replay --input OUT.mcap --config robot_config/tracker.toml \\
        --color-topic /camera/color/image_raw/compressed \\
        --depth-topic /camera/depth/image_raw/compressedDepth --trajectory traj.txt

The intrinsics are TUM fr3's (robot_config/cameras/tum_fr3.toml); pass --fx etc. for others.
"""
import argparse
import io
import struct
from pathlib import Path

from make_mcap_fixture import CAMERA_INFO, COMPRESSED_IMAGE, camera_info, header


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--first-frame", type=int, default=0)
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--quality", type=int, default=90, help="JPEG quality (default 90)")
    ap.add_argument("--fx", type=float, default=535.4)
    ap.add_argument("--fy", type=float, default=539.2)
    ap.add_argument("--cx", type=float, default=320.1)
    ap.add_argument("--cy", type=float, default=247.6)
    a = ap.parse_args()
    from mcap_ros2.writer import Writer
    from PIL import Image

    pairs = []
    for line in (a.dataset / "associations.txt").read_text().splitlines():
        f = line.split()
        if len(f) != 4 or line.startswith("#"):
            continue
        first, second = (f[0], f[1]), (f[2], f[3])
        depth, colour = (first, second) if first[1].startswith("depth") else (second, first)
        pairs.append((depth, colour))
    end = None if a.max_frames is None else a.first_frame + a.max_frames
    pairs = pairs[a.first_frame:end]
    with open(a.out, "wb") as f:
        w = Writer(f)
        image = w.register_msgdef("sensor_msgs/msg/CompressedImage", COMPRESSED_IMAGE)
        info = w.register_msgdef("sensor_msgs/msg/CameraInfo", CAMERA_INFO)
        for (d_stamp, d_file), (c_stamp, c_file) in pairs:
            d_ns, c_ns = round(float(d_stamp) * 1e9), round(float(c_stamp) * 1e9)
            colour = Image.open(a.dataset / c_file).convert("RGB")
            depth = Image.open(a.dataset / d_file)
            width, height = colour.size
            cam = camera_info(header(d_ns), width, height, a.fx, a.fy, a.cx, a.cy)
            w.write_message("/camera/color/camera_info", info, cam, log_time=d_ns, publish_time=d_ns)
            jpeg = io.BytesIO()
            colour.save(jpeg, "JPEG", quality=a.quality)
            w.write_message("/camera/color/image_raw/compressed", image,
                            {"header": header(c_ns), "format": "rgb8; jpeg compressed bgr8", "data": jpeg.getvalue()},
                            log_time=c_ns, publish_time=c_ns)
            # TUM depth is 1/5000 m; compressedDepth 16UC1 is mm (rounded).
            mm = [(v + 2) // 5 for v in depth.get_flattened_data()]
            png = io.BytesIO()
            Image.frombytes("I;16", depth.size, struct.pack("<%dH" % len(mm), *mm)).save(png, "PNG")
            data = struct.pack("<iff", 0, 0.0, 0.0) + png.getvalue()
            w.write_message("/camera/depth/image_raw/compressedDepth", image,
                            {"header": header(d_ns), "format": "16UC1; compressedDepth png", "data": data},
                            log_time=d_ns, publish_time=d_ns)
        w.finish()
    print(f"wrote {len(pairs)} frames to {a.out}")


if __name__ == "__main__":
    main()
