"""TUM trajectory files (`stamp tx ty tz qx qy qz qw` per line) for the scripts here:
one reader, shared by orientation_residuals.py and step_lengths.py. Needs numpy."""
import sys

import numpy as np


def rotation(q):
    """The rotation matrix of the quaternion `qx qy qz qw` (normalised first)."""
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def load(path):
    """(stamps, poses) of a TUM trajectory file: a numpy array of stamps in s and a list
    of 4×4 homogeneous poses. Exits with a message naming the file and line on a file
    that cannot be read, a line without 8 columns or a field that is not a number, and
    on a file without poses."""
    stamps, poses = [], []
    try:
        f = open(path)
    except OSError as e:
        sys.exit(f"{path}: cannot read: {e.strerror}")
    with f:
        for number, line in enumerate(f, 1):
            if line.startswith("#") or not line.strip():
                continue
            v = line.split()
            if len(v) != 8:
                sys.exit(f"{path}:{number}: expected 8 columns (stamp tx ty tz qx qy qz qw), got {len(v)}")
            try:
                v = [float(x) for x in v]
            except ValueError:
                sys.exit(f"{path}:{number}: not a number in {line.strip()!r}")
            m = np.eye(4)
            m[:3, :3] = rotation(v[4:8])
            m[:3, 3] = v[1:4]
            stamps.append(v[0])
            poses.append(m)
    if not poses:
        sys.exit(f"{path}: no poses")
    return np.array(stamps), poses
