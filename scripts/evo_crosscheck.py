#!/usr/bin/env python3
"""Cross-check `mrsmap eval` against evo (PyPI) on the same files, to 0.01 mm.

usage: evo_crosscheck.py MRSMAP_BINARY GROUNDTRUTH ESTIMATE

The evo computation is the one of these command lines:
  evo_rpe tum GT EST --delta 1 --delta_unit f --t_max_diff 0.02 -r trans_part
  evo_ape tum GT EST -a --t_max_diff 0.02 -r trans_part
"""
import subprocess
import sys

from evo.core import metrics, sync
from evo.tools import file_interface

TOLERANCE_M = 1e-5  # 0.01 mm


def mrsmap_stats(binary, metric, gt, est):
    out = subprocess.run([binary, "eval", metric, gt, est], check=True, capture_output=True, text=True).stdout
    stats = {}
    for line in out.splitlines()[1:]:
        name, value, unit = line.split()
        assert unit == "mm", line
        stats[name] = float(value) * 1e-3
    return stats


def evo_stats(metric, gt_path, est_path):
    gt = file_interface.read_tum_trajectory_file(gt_path)
    est = file_interface.read_tum_trajectory_file(est_path)
    gt, est = sync.associate_trajectories(gt, est, max_diff=0.02)
    if metric == "rpe":
        m = metrics.RPE(metrics.PoseRelation.translation_part, 1, metrics.Unit.frames, all_pairs=False)
    else:
        est.align(gt, correct_scale=False)
        m = metrics.APE(metrics.PoseRelation.translation_part)
    m.process_data((gt, est))
    return m.get_all_statistics()


def main():
    binary, gt, est = sys.argv[1:4]
    worst = 0.0
    for metric in ["rpe", "ate"]:
        ours = mrsmap_stats(binary, metric, gt, est)
        theirs = evo_stats(metric, gt, est)
        for name in ["rmse", "mean", "median", "std", "min", "max"]:
            diff = abs(ours[name] - theirs[name])
            worst = max(worst, diff)
            print(f"{metric} {name:6s} mrsmap {ours[name] * 1e3:10.4f} mm   evo {theirs[name] * 1e3:10.4f} mm   |diff| {diff * 1e3:.5f} mm")
            if diff > TOLERANCE_M:
                sys.exit(f"{metric} {name} differs from evo by {diff * 1e3:.5f} mm (> 0.01 mm)")
    print(f"agreement with evo: largest difference {worst * 1e3:.5f} mm (tolerance 0.01 mm)")


if __name__ == "__main__":
    main()
