#!/usr/bin/env python3
"""How long an odometry's estimated steps are against the ground truth's, by speed.

    scripts/step_lengths.py GROUNDTRUTH TRAJECTORY [--window K] [--max-interval S]

TRAJECTORY is a TUM trajectory of `mrsmap odometry` (world_from_camera). Each estimate
is matched to the ground-truth pose nearest in time (within 0.02 s), as `mrsmap eval
rpe` matches them. For each pair of consecutive frames, the script compares the
estimated step (the translation of the relative pose) with the true one: it projects
the estimate on the true step and divides by the true step's length (1: as long, below
1: short).

Pairs further apart than --max-interval (default 0.045 s, i.e. one period of a 30 Hz
camera) are left out: they are frames dropped by the recording, and the TUM stamps
place them badly (docs/evaluation.md). The medians are printed three ways:

- sorted by the pair's own true step. Noise in the ground truth makes the largest true
  steps partly noise, so this sort finds short estimates there even when there are none
  (regression to the mean);
- sorted by the estimated step, which has the same fault the other way round;
- sorted by the true speed over the K pairs on either side (--window, default 3), not
  counting the pair itself. This is the independent sort; read this one.

Needs numpy (installed with evo by .ci/run).
"""
import argparse
import signal
import sys

import numpy as np

from tum_poses import load

BINS_MM = [(0.0, 10.0), (10.0, 15.0), (15.0, 30.0), (30.0, float("inf"))]
MAX_STAMP_GAP_S = 0.02


def steps(gt, est):
    """(true step in m, estimated step in m, projection ratio, interval in s) per pair of
    consecutive estimates that both have a ground-truth match."""
    gt_stamps, gt_poses = gt
    est_stamps, est_poses = est
    matched = []
    for i, s in enumerate(est_stamps):
        j = int(np.argmin(np.abs(gt_stamps - s)))
        if abs(gt_stamps[j] - s) <= MAX_STAMP_GAP_S:
            matched.append((i, j))
    rows = []
    for (i0, j0), (i1, j1) in zip(matched, matched[1:]):
        true_step = (np.linalg.inv(gt_poses[j0]) @ gt_poses[j1])[:3, 3]
        est_step = (np.linalg.inv(est_poses[i0]) @ est_poses[i1])[:3, 3]
        length = np.linalg.norm(true_step)
        ratio = est_step @ true_step / length**2 if length > 0 else np.nan
        rows.append((length, np.linalg.norm(est_step), ratio, est_stamps[i1] - est_stamps[i0]))
    return np.array(rows).reshape(-1, 4)


def window_speed(rows, k, period):
    """True step per period over the k pairs on either side of each pair (not itself)."""
    speed = np.full(len(rows), np.nan)
    for i in range(len(rows)):
        near = np.r_[rows[max(0, i - k):i], rows[i + 1:i + 1 + k]]
        if len(near):
            speed[i] = np.mean(near[:, 0] / near[:, 3]) * period
    return speed


def table(title, key_m, rows):
    print(f"  sorted by {title}:")
    for lo, hi in BINS_MM:
        inside = (key_m * 1000 >= lo) & (key_m * 1000 < hi)
        if inside.any():
            r = rows[inside, 2]
            print(f"    {lo:4.0f}–{hi:<4.0f} mm: {inside.sum():4d} pairs, median {np.nanmedian(r):.3f}")


def main():
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # quiet when piped into `head`
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("groundtruth")
    ap.add_argument("trajectory")
    ap.add_argument("--window", type=int, default=3, help="pairs on either side for the speed (default 3)")
    ap.add_argument("--max-interval", type=float, default=0.045, help="longest pair interval kept, s (default 0.045)")
    a = ap.parse_args()
    if a.window < 1:
        sys.exit(f"--window {a.window}: give at least 1")
    gt, est = load(a.groundtruth), load(a.trajectory)
    for path, (stamps, _) in ((a.groundtruth, gt), (a.trajectory, est)):
        if len(stamps) < 2:
            sys.exit(f"{path}: fewer than two poses")
    rows = steps(gt, est)
    period = np.median(rows[:, 3]) if len(rows) else 0.0
    one_period = rows[:, 3] <= a.max_interval
    kept = rows[one_period]
    if len(kept) == 0:
        sys.exit("no pair of consecutive estimates within --max-interval matches the ground truth")
    speed = window_speed(rows, a.window, period)[one_period]
    print(f"{len(kept)} of {len(rows)} pairs at most {a.max_interval} s apart (period {period * 1000:.1f} ms)")
    print(f"estimated step projected on the true one, over its length: median {np.nanmedian(kept[:, 2]):.3f}")
    table("the pair's own true step (biased: see --help)", kept[:, 0], kept)
    table("the estimated step (biased the other way)", kept[:, 1], kept)
    table(f"the true speed over {a.window} pairs on either side, per period", speed, kept)


if __name__ == "__main__":
    main()
