#!/usr/bin/env python3
"""Writes the MCAP fixtures in tests/data with independent writers (not mrsmap's):

- tests/data/python_ros2.mcap: the Python `mcap` + `mcap-ros2-support` writer, ROS 2
  sensor_msgs/msg/Image and CameraInfo. Topics /camera/color/image_raw (rgb8),
  /camera/depth/image_raw (16UC1, mm), /camera/color/camera_info, and a second set
  /alt/color (bgr8), /alt/depth (32FC1, m), /alt/camera_info.
- tests/data/python_foxglove.mcap: `mcap-protobuf-support` with the Foxglove schemas
  (foxglove.RawImage rgb8 and 16UC1, foxglove.CameraCalibration) on the same default topics.
- tests/data/python_ros2_compressed.mcap: sensor_msgs/msg/CompressedImage as ROS 2's
  image_transport writes it: colour "rgb8; jpeg compressed bgr8" (JPEG, quality 95, no
  chroma subsampling) on /camera/color/image_raw/compressed, depth "16UC1; compressedDepth
  png" on /camera/depth/image_raw/compressedDepth and "32FC1; compressedDepth png"
  (quantised inverse depth, image_transport's defaults: depth_max 10 m, quantisation 100)
  on /alt/depth/compressedDepth; CameraInfo on /camera/color/camera_info.
- tests/data/python_foxglove_compressed.mcap: foxglove.CompressedImage, colour "png" and
  depth "png" (16-bit grey, mm) on the default topics, with foxglove.CameraCalibration.

Images are 64x48 with pixel values given by a formula the Rust test repeats
(tests/mcap_interop.rs): colour (u*7 + v*3 + i, u + 5*v, 40*i + u) mod 256, depth
500 + 10*u + v + i mm, frame i stamped 1.0 + i/30 s (colour 5 ms before depth).

    python3 -m pip install 'mcap==1.6.0' 'mcap-ros2-support==0.6.0' \
        'mcap-protobuf-support==0.6.0' 'foxglove-schemas-protobuf==0.4.0' 'pillow==13.0.0'
    python3 scripts/make_mcap_fixture.py
"""
import io
import struct
import sys
from pathlib import Path

W, H, N = 64, 48, 3
FX, FY, CX, CY = 52.5, 53.0, 31.5, 23.5

TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
SEP = "=" * 80 + "\n"
IMAGE = ("std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n"
         "uint32 step\nuint8[] data\n" + SEP + HEADER + SEP + TIME)
CAMERA_INFO = ("std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n"
               "float64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\n"
               "sensor_msgs/RegionOfInterest roi\n" + SEP + HEADER + SEP + TIME + SEP
               + "MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\n"
               "uint32 width\nbool do_rectify\n")


def colour(i):
    return [((u * 7 + v * 3 + i) % 256, (u + 5 * v) % 256, (40 * i + u) % 256) for v in range(H) for u in range(W)]


def depth_mm(i):
    return [500 + 10 * u + v + i for v in range(H) for u in range(W)]


def stamps(i):
    depth_ns = 1_000_000_000 + i * 1_000_000_000 // 30
    return depth_ns - 5_000_000, depth_ns


def stamp(ns):
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def header(ns):
    """A std_msgs/Header in the colour camera's optical frame."""
    return {"stamp": stamp(ns), "frame_id": "camera_color_optical_frame"}


def camera_info(msg_header, width, height, fx, fy, cx, cy):
    """A sensor_msgs/msg/CameraInfo of a pinhole camera without distortion."""
    return {"header": msg_header, "height": height, "width": width, "distortion_model": "plumb_bob",
            "d": [0.0] * 5, "k": [fx, 0, cx, 0, fy, cy, 0, 0, 1], "r": [1, 0, 0, 0, 1, 0, 0, 0, 1],
            "p": [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], "binning_x": 0, "binning_y": 0,
            "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False}}


def foxglove_calibration(ns):
    from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
    cal = CameraCalibration(width=W, height=H, distortion_model="plumb_bob", D=[0.0] * 5,
                            K=[FX, 0, CX, 0, FY, CY, 0, 0, 1], R=[1, 0, 0, 0, 1, 0, 0, 0, 1],
                            P=[FX, 0, CX, 0, 0, FY, CY, 0, 0, 0, 1, 0], frame_id="camera")
    cal.timestamp.FromNanoseconds(ns)
    return cal


def ros2(path):
    from mcap_ros2.writer import Writer
    with open(path, "wb") as f:
        w = Writer(f)
        image = w.register_msgdef("sensor_msgs/msg/Image", IMAGE)
        info = w.register_msgdef("sensor_msgs/msg/CameraInfo", CAMERA_INFO)
        for i in range(N):
            c_ns, d_ns = stamps(i)
            cam = camera_info(header(d_ns), W, H, FX, FY, CX, CY)
            rgb = bytes(x for p in colour(i) for x in p)
            bgr = bytes(x for p in colour(i) for x in reversed(p))
            mm = struct.pack("<%dH" % (W * H), *depth_mm(i))
            metres = struct.pack("<%df" % (W * H), *(d / 1000.0 for d in depth_mm(i)))
            for prefix, info_topic, c_enc, c_data, d_enc, d_data, d_bpp in [
                ("/camera/color/image_raw", "/camera/color/camera_info", "rgb8", rgb, "16UC1", mm, 2),
                ("/alt/color", "/alt/camera_info", "bgr8", bgr, "32FC1", metres, 4),
            ]:
                depth_topic = "/camera/depth/image_raw" if prefix.startswith("/camera") else "/alt/depth"
                w.write_message(info_topic, info, cam, log_time=d_ns, publish_time=d_ns)
                w.write_message(prefix, image, {"header": header(c_ns), "height": H, "width": W, "encoding": c_enc,
                                                "is_bigendian": 0, "step": 3 * W, "data": c_data},
                                log_time=c_ns, publish_time=c_ns)
                w.write_message(depth_topic, image, {"header": header(d_ns), "height": H, "width": W,
                                                     "encoding": d_enc, "is_bigendian": 0, "step": d_bpp * W,
                                                     "data": d_data},
                                log_time=d_ns, publish_time=d_ns)
        w.finish()


def foxglove_file(path, colour_message, depth_message):
    """Frames with foxglove.CameraCalibration; `colour_message(i)` and `depth_message(i)` make
    frame i's images (stamped here)."""
    from mcap_protobuf.writer import Writer
    with open(path, "wb") as f, Writer(f) as w:
        for i in range(N):
            c_ns, d_ns = stamps(i)
            w.write_message("/camera/color/camera_info", foxglove_calibration(d_ns), log_time=d_ns, publish_time=d_ns)
            for topic, message, ns in [("/camera/color/image_raw", colour_message(i), c_ns),
                                       ("/camera/depth/image_raw", depth_message(i), d_ns)]:
                message.timestamp.FromNanoseconds(ns)
                w.write_message(topic, message, log_time=ns, publish_time=ns)


def foxglove(path):
    from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
    foxglove_file(path,
                  lambda i: RawImage(width=W, height=H, encoding="rgb8", step=3 * W, frame_id="camera",
                                     data=bytes(x for p in colour(i) for x in p)),
                  lambda i: RawImage(width=W, height=H, encoding="16UC1", step=2 * W, frame_id="camera",
                                     data=struct.pack("<%dH" % (W * H), *depth_mm(i))))


COMPRESSED_IMAGE = "std_msgs/Header header\nstring format\nuint8[] data\n" + SEP + HEADER + SEP + TIME
# image_transport's compressedDepth defaults (depth_max 10 m, depth_quantization 100).
QUANT_A = 100.0 * 101.0
QUANT_B = 1.0 - QUANT_A / 10.0


def jpeg(i):
    from PIL import Image
    out = io.BytesIO()
    Image.frombytes("RGB", (W, H), bytes(x for p in colour(i) for x in p)).save(out, "JPEG", quality=95, subsampling=0)
    return out.getvalue()


def png_rgb(i):
    from PIL import Image
    out = io.BytesIO()
    Image.frombytes("RGB", (W, H), bytes(x for p in colour(i) for x in p)).save(out, "PNG")
    return out.getvalue()


def png16(values):
    from PIL import Image
    out = io.BytesIO()
    Image.frombytes("I;16", (W, H), struct.pack("<%dH" % (W * H), *values)).save(out, "PNG")
    return out.getvalue()


def compressed_depth(i, metres):
    # struct ConfigHeader { int32 format (INV_DEPTH = 0); float depthParam[2]; }
    config = struct.pack("<iff", 0, QUANT_A if metres else 0.0, QUANT_B if metres else 0.0)
    if metres:
        values = [round(QUANT_A / (d / 1000.0) + QUANT_B) for d in depth_mm(i)]
    else:
        values = depth_mm(i)
    return config + png16(values)


def ros2_compressed(path):
    from mcap_ros2.writer import Writer
    with open(path, "wb") as f:
        w = Writer(f)
        image = w.register_msgdef("sensor_msgs/msg/CompressedImage", COMPRESSED_IMAGE)
        info = w.register_msgdef("sensor_msgs/msg/CameraInfo", CAMERA_INFO)
        for i in range(N):
            c_ns, d_ns = stamps(i)
            cam = camera_info(header(d_ns), W, H, FX, FY, CX, CY)
            w.write_message("/camera/color/camera_info", info, cam, log_time=d_ns, publish_time=d_ns)
            w.write_message("/camera/color/image_raw/compressed", image,
                            {"header": header(c_ns), "format": "rgb8; jpeg compressed bgr8", "data": jpeg(i)},
                            log_time=c_ns, publish_time=c_ns)
            w.write_message("/camera/depth/image_raw/compressedDepth", image,
                            {"header": header(d_ns), "format": "16UC1; compressedDepth png",
                             "data": compressed_depth(i, False)},
                            log_time=d_ns, publish_time=d_ns)
            w.write_message("/alt/depth/compressedDepth", image,
                            {"header": header(d_ns), "format": "32FC1; compressedDepth png",
                             "data": compressed_depth(i, True)},
                            log_time=d_ns, publish_time=d_ns)
        w.finish()


def foxglove_compressed(path):
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    foxglove_file(path,
                  lambda i: CompressedImage(frame_id="camera", format="png", data=png_rgb(i)),
                  lambda i: CompressedImage(frame_id="camera", format="png", data=png16(depth_mm(i))))


if __name__ == "__main__":
    out = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "tests" / "data")
    ros2(out / "python_ros2.mcap")
    foxglove(out / "python_foxglove.mcap")
    ros2_compressed(out / "python_ros2_compressed.mcap")
    foxglove_compressed(out / "python_foxglove_compressed.mcap")
    print("wrote python_ros2.mcap, python_foxglove.mcap, python_ros2_compressed.mcap and",
          "python_foxglove_compressed.mcap to", out)
