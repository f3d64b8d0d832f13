#!/usr/bin/env python3
"""Renders a TUM RGB-D sequence as a camera with lens distortion would have seen it,
using OpenCV (an implementation independent of ours): for every pixel of the distorted
image, `cv2.undistortPoints` gives the pinhole pixel it sees, which is sampled with
`cv2.remap` (colour bilinear, depth nearest, so no depth is invented across edges).
Depth along the optical axis does not change under lens distortion. Pixels that see
outside the pinhole image stay empty (depth 0, black).

Writes DIR/rgb, DIR/depth, associations.txt, groundtruth.txt (copied) and a camera
file for `mrsmap --camera`. Used by scripts/distortion_check.sh.

    pip install opencv-python-headless==5.0.0.93 numpy
    scripts/distort_dataset.py ../shared/data/tum/fr3_teddy_first200 /tmp/teddy_rational \\
        --fx 535.4 --fy 539.2 --cx 320.1 --cy 247.6 \\
        --distortion 0.45 -2.5 0.0007 -0.0003 1.4 0.33 -2.35 1.35 --first 100
"""
import argparse, pathlib, shutil

import cv2
import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("src", type=pathlib.Path, help="TUM sequence with associations.txt")
    ap.add_argument("dst", type=pathlib.Path, help="output folder (created)")
    for k in ("fx", "fy", "cx", "cy"):
        ap.add_argument(f"--{k}", type=float, required=True, help="pinhole intrinsics of SRC and of the output")
    ap.add_argument("--distortion", type=float, nargs="+", required=True,
                    help="5 (plumb_bob) or 8 (rational_polynomial) coefficients, OpenCV order")
    ap.add_argument("--depth-scale-m", type=float, default=1 / 5000)
    ap.add_argument("--first", type=int, default=0, help="first frame (index in associations.txt)")
    ap.add_argument("--count", type=int, default=None, help="number of frames (default: all)")
    a = ap.parse_args()
    if len(a.distortion) not in (5, 8):
        ap.error(f"--distortion takes 5 or 8 coefficients, got {len(a.distortion)}")

    lines = [l for l in (a.src / "associations.txt").read_text().splitlines() if l.strip() and not l.startswith("#")]
    lines = lines[a.first:] if a.count is None else lines[a.first:a.first + a.count]
    if not lines:
        raise SystemExit(f"{a.src}: no frames from index {a.first}")
    first = cv2.imread(str(a.src / lines[0].split()[1]), cv2.IMREAD_COLOR)
    h, w = first.shape[:2]
    k = np.array([[a.fx, 0, a.cx], [0, a.fy, a.cy], [0, 0, 1.0]])
    d = np.array(a.distortion)
    # Pinhole pixel seen by each distorted pixel (P = K: back into pixel units).
    grid = np.stack(np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)), -1)
    seen = cv2.undistortPoints(grid.reshape(-1, 1, 2), k, d, P=k,
                               criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12))
    map_x = seen[:, 0, 0].reshape(h, w).astype(np.float32)
    map_y = seen[:, 0, 1].reshape(h, w).astype(np.float32)

    for sub in ("rgb", "depth"):
        (a.dst / sub).mkdir(parents=True, exist_ok=True)
    for line in lines:
        _, rgb, _, depth = line.split()
        colour = cv2.imread(str(a.src / rgb), cv2.IMREAD_COLOR)
        depth_img = cv2.imread(str(a.src / depth), cv2.IMREAD_UNCHANGED)
        if colour is None or depth_img is None or depth_img.dtype != np.uint16:
            raise SystemExit(f"{a.src}: cannot read {rgb} / {depth} as 8-bit colour and 16-bit depth")
        cv2.imwrite(str(a.dst / rgb), cv2.remap(colour, map_x, map_y, cv2.INTER_LINEAR,
                                                borderMode=cv2.BORDER_CONSTANT, borderValue=0))
        cv2.imwrite(str(a.dst / depth), cv2.remap(depth_img, map_x, map_y, cv2.INTER_NEAREST,
                                                  borderMode=cv2.BORDER_CONSTANT, borderValue=0))
    (a.dst / "associations.txt").write_text("\n".join(lines) + "\n")
    shutil.copy(a.src / "groundtruth.txt", a.dst / "groundtruth.txt")
    coefficients = ", ".join(repr(c) for c in a.distortion)
    (a.dst / "camera.toml").write_text(
        f"# {a.src.name} re-rendered through lens distortion by scripts/distort_dataset.py\n"
        f'name = "{a.dst.name}"\nwidth = {w}\nheight = {h}\n'
        f"fx = {a.fx}\nfy = {a.fy}\ncx = {a.cx}\ncy = {a.cy}\n"
        f"distortion = [{coefficients}]\ndepth_scale_m = {a.depth_scale_m}\n")
    print(f"{len(lines)} frames of {a.src} written to {a.dst} ({w}x{h}, {len(d)} coefficients)")


if __name__ == "__main__":
    main()
