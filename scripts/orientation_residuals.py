#!/usr/bin/env python3
"""Per-frame orientation error of a TUM trajectory against the ground truth, in the
camera's own axes: log(R_gtᵀ R_est) in degrees (x right, y down, z = optical axis).

    scripts/orientation_residuals.py GROUNDTRUTH TRAJECTORY [--world-from-model tx ty tz qx qy qz qw] [--fit] [--rate]

TRAJECTORY holds world_from_camera (mrsmap map --trajectory), or object_from_camera
(mrsmap track --trajectory) with --world-from-model as `mrsmap model info` prints it.
Poses are matched to the nearest ground-truth stamp within 0.02 s. Prints the mean and
spread, then every 8th frame. With --fit, also how much of the error a fitted rotation
of the world explains, and a world rotation together with a constant camera-side one (a
marker-to-camera calibration error): the RMS left and the fitted rotations. With --rate,
how the errors follow the camera's angular rate (from the ground truth over ±5 samples,
per-axis means removed): their correlation and the lag it implies. Needs numpy
(installed with evo by .ci/run).
"""
import argparse
import sys

import numpy as np

from tum_poses import load, rotation


def log_deg(r):
    angle = np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))
    if angle < 1e-12:
        return np.zeros(3)
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (2 * np.sin(angle))
    return np.degrees(angle * axis)


def nearest_rotation(m):
    u, _, vt = np.linalg.svd(m)
    return u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt


def fit(pairs, camera_side):
    """World rotation `a` (and camera-side `d`) minimising Σ ‖a·R_est − R_gt·d‖² (chordal),
    by alternating closed-form steps."""
    a, d = np.eye(3), np.eye(3)
    for _ in range(200 if camera_side else 1):  # with d fixed, one step is the optimum
        a = nearest_rotation(sum(g @ d @ e.T for g, e in pairs))
        if camera_side:
            d = nearest_rotation(sum(g.T @ a @ e for g, e in pairs))
    r = np.array([log_deg((g @ d).T @ a @ e) for g, e in pairs])
    return a, d, np.sqrt((r ** 2).sum(1).mean())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("groundtruth")
    ap.add_argument("trajectory")
    ap.add_argument("--world-from-model", nargs=7, type=float, metavar="V")
    ap.add_argument("--fit", action="store_true", help="fit a world rotation, then also a camera-side one")
    ap.add_argument("--rate", action="store_true", help="correlate the errors with the angular rate")
    a = ap.parse_args()
    stamps, gt_poses = load(a.groundtruth)
    gt = [(t, p[:3, :3]) for t, p in zip(stamps, gt_poses)]
    pre = rotation(a.world_from_model[3:]) if a.world_from_model else np.eye(3)
    pairs, rates = [], []
    for t, p in zip(*load(a.trajectory)):
        r = p[:3, :3]
        i = int(np.argmin(abs(stamps - t)))
        if abs(stamps[i] - t) < 0.02:
            pairs.append((gt[i][1], pre @ r))
            lo, hi = max(i - 5, 0), min(i + 5, len(gt) - 1)
            rates.append(log_deg(gt[lo][1].T @ gt[hi][1]) / max(stamps[hi] - stamps[lo], 1e-9))
    residuals = [log_deg(g.T @ e) for g, e in pairs]
    if not residuals:
        sys.exit("no pose has a ground-truth stamp within 0.02 s")
    r = np.array(residuals)
    print(f"{len(r)} frames; camera-frame error (deg, x y z): mean {r.mean(0).round(2)}, "
          f"spread {r.std(0).round(2)}, median |error| {np.median(np.linalg.norm(r, axis=1)):.2f}")
    for k in range(0, len(r), 8):
        print(f"  frame {k:3d}: {r[k].round(2)}")
    if a.rate:
        e = (r - r.mean(0)).ravel()
        w = np.array(rates)
        w = (w - w.mean(0)).ravel()
        print(f"correlation with the angular rate {np.corrcoef(e, w)[0, 1]:.2f}: "
              f"as if the estimate lagged by {-np.dot(e, w) / np.dot(w, w) * 1000:.1f} ms")
    if a.fit:
        w, _, rms = fit(pairs, False)
        print(f"fitted world rotation {log_deg(w).round(2)}: RMS left {rms:.2f}")
        w, d, rms = fit(pairs, True)
        print(f"fitted world rotation {log_deg(w).round(2)} and camera-side {log_deg(d).round(2)}: RMS left {rms:.2f}")


if __name__ == "__main__":
    main()
