#!/usr/bin/env bash
# Odometry and SLAM accuracy on the real TUM sequences in ../shared/data/tum (with motion-capture
# ground truth): odometry by translational RPE at a delta of one frame, SLAM by ATE RMSE
# (TUM definitions, as evo). Odometry runs at the default λ = 0.01 and at λ = 0.007.
#
# Prints each result next to the targets of the foundation issue (10 % below the
# authors' original implementation measured on this machine, max no higher) and fails
# only on a regression beyond the recorded guard values (docs/evaluation.md): the
# targets themselves are reported, not asserted, so a miss is visible rather than hidden.
# Then cross-checks `mrsmap eval` against evo on one trajectory (needs `pip install evo`),
# and prints the teddy's odometry step lengths against the ground truth by speed.
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${MRSMAP_TUM:-../shared/data/tum}
BIN=target/release/mrsmap
[ -d "$DATA" ] || { echo "accuracy: $DATA not found (set MRSMAP_TUM)"; exit 1; }
cargo build --release --quiet
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
status=0
#        sequence            camera  flags   target median/max  guard median/max
while read -r seq cam flags tmed tmax gmed gmax; do
  [ "$flags" = "-" ] && flags=""
  traj="$OUT/$seq${flags// /}.txt"
  $BIN odometry --dataset "$DATA/$seq" --camera "robot_config/cameras/$cam.toml" --out "$traj" $flags > "$OUT/log" 2>&1 \
    || { cat "$OUT/log"; exit 1; }
  read -r med max < <($BIN eval rpe "$DATA/$seq/groundtruth.txt" "$traj" | awk '/median/ {m=$2} /max/ {x=$2} END {print m, x}')
  verdict=$(awk -v m="$med" -v x="$max" -v tm="$tmed" -v tx="$tmax" 'BEGIN {
    if (tm == "-") { print "(no figure of the original to compare)"; exit }
    printf "%s median (target <= %s), %s max (target <= %s)", (m <= tm ? "meets" : "MISSES"), tm, (x <= tx ? "meets" : "MISSES"), tx }')
  printf '%-20s %-7s RPE median %6.3f mm  max %7.3f mm   %s\n' "$seq" "${flags:-VGA}" "$med" "$max" "$verdict"
  if awk -v m="$med" -v x="$max" -v gm="$gmed" -v gx="$gmax" 'BEGIN {exit !(m > gm || x > gx)}'; then
    echo "  REGRESSION: guard is median <= $gmed mm, max <= $gmax mm"
    status=1
  fi
  grep -q " 0 failed, 0 skipped" "$OUT/log" || { echo "  frames failed or skipped:"; grep odometry: "$OUT/log"; status=1; }
done <<'TABLE'
fr3_teddy_first200 tum_fr3 -      2.43 15.2 2.00 16.8
fr3_teddy_first200 tum_fr3 --qvga - - 2.35 14.8
fr1_xyz_first37    tum_fr1 -      2.55 6.0  2.65 5.6
fr1_xyz_first37    tum_fr1 --qvga - - 2.55 6.2
fr1_desk_9frames   tum_fr1 -      - -       2.80 4.8
fr3_teddy_first200 tum_fr3 --lambda=0.007 2.43 15.2 2.15 14.5
fr1_xyz_first37    tum_fr1 --lambda=0.007 2.55 6.0  2.45 6.0
TABLE
# SLAM (mapping tool): ATE RMSE after Horn alignment, every frame.
#        sequence            camera  target  guard (mm)
while read -r seq cam target guard; do
  traj="$OUT/slam_$seq.txt"
  $BIN map --dataset "$DATA/$seq" --camera "robot_config/cameras/$cam.toml" --trajectory "$traj" > "$OUT/log" 2>&1 \
    || { cat "$OUT/log"; exit 1; }
  ate=$($BIN eval ate "$DATA/$seq/groundtruth.txt" "$traj" | awk '/rmse/ {print $2}')
  verdict=$(awk -v a="$ate" -v t="$target" 'BEGIN { if (t == "-") print "(no figure of the original to compare)";
    else printf "%s (target <= %s)", (a <= t ? "meets" : "MISSES"), t }')
  printf '%-20s SLAM    ATE RMSE %6.2f mm   %s; %s\n' "$seq" "$ate" "$verdict" "$(grep -o '[0-9]* key views, [0-9]* edges' "$OUT/log")"
  if awk -v a="$ate" -v g="$guard" 'BEGIN {exit !(a > g)}'; then
    echo "  REGRESSION: guard is ATE <= $guard mm"
    status=1
  fi
done <<'TABLE'
fr3_teddy_first200 tum_fr3 14.0 13.0
fr1_xyz_first37    tum_fr1 -    4.0
fr1_desk_9frames   tum_fr1 -    3.0
TABLE
# Object tracking (tracker step over frames 100-199; the teddy model was learned from
# frames 0-99): camera position error, TUM ATE after rigid alignment, median (target <= 10 mm).
# Fast motion: every 4th frame only (~40 mm and ~4 degrees between tracked frames), as a
# tracker four camera periods behind sees it. Every frame must stay tracked.
#        flags      frames
while read -r flags frames; do
  [ "$flags" = "-" ] && flags=""
  out=$($BIN track --config robot_config/tracker.toml --dataset "$DATA/fr3_teddy_first200" \
    --camera robot_config/cameras/tum_fr3.toml --first-frame 100 --start-at-ground-truth $flags)
  line=$(echo "$out" | grep "ATE (aligned)")
  med=$(echo "$line" | sed -E 's/.*ATE \(aligned\) median ([0-9.]+) mm.*/\1/')
  # Frames whose pose was estimated from them: tracking, less those held after a failure.
  tracked=$(echo "$out" | sed -nE 's/.* ([0-9]+) frames tracking \(([0-9]+) held\).*/\1 \2/p' | awk '{print $1 - $2}')
  printf '%-20s track   %-9s %s   %s\n' fr3_teddy_100-199 "${flags:-VGA}" "$(echo "$line" | sed -E 's/^ *camera position error vs ground truth //')" \
    "$(awk -v m="$med" 'BEGIN { printf "%s (target median <= 10 mm)", (m <= 10 ? "meets" : "MISSES") }')"
  if awk -v m="$med" -v n="$tracked" -v f="$frames" 'BEGIN {exit !(m > 8.5 || n < f)}'; then
    echo "  REGRESSION: guard is ATE median <= 8.5 mm with all $frames frames tracking ($tracked)"; status=1
  fi
done <<'TABLE'
-         93
--qvga    93
--every=4 24
TABLE
# Faster still: every 13th frame (0.43 s between tracked frames). The constant-velocity
# prediction fails on some frames; the retry from the last pose must keep all 8 tracked.
out=$($BIN track --config robot_config/tracker.toml --dataset "$DATA/fr3_teddy_first200" \
  --camera robot_config/cameras/tum_fr3.toml --first-frame 100 --start-at-ground-truth --every 13)
tracked=$(echo "$out" | sed -nE 's/.* ([0-9]+) frames tracking \(([0-9]+) held\).*/\1 \2/p' | awk '{print $1 - $2}')
printf '%-20s track   %-9s %s of 8 frames estimated from their own frame\n' fr3_teddy_100-199 --every=13 "$tracked"
if [ "$tracked" != 8 ]; then echo "  REGRESSION: guard is all 8 frames tracked"; status=1; fi
# MCAP replay: the same frames as a ROS 2 recording (16UC1 depth in mm), replayed from the
# configured start pose (the first frame of tests/data/fr3_teddy_8 is frame 100).
$BIN convert tum-to-mcap "$DATA/fr3_teddy_first200" --first-frame 100 --out "$OUT/teddy100.mcap" >/dev/null
$BIN replay --input "$OUT/teddy100.mcap" --config robot_config/tracker.toml --trajectory "$OUT/replay.txt" >/dev/null
med=$($BIN eval ate "$DATA/fr3_teddy_first200/groundtruth.txt" "$OUT/replay.txt" | awk '/median/ {print $2}')
n=$(grep -vc '^#' "$OUT/replay.txt")
printf '%-20s replay  MCAP    %d frames tracked, ATE median %.1f mm   %s\n' fr3_teddy_100-199 "$n" "$med" \
  "$(awk -v m="$med" 'BEGIN { printf "%s (target median <= 10 mm)", (m <= 10 ? "meets" : "MISSES") }')"
if awk -v m="$med" -v n="$n" 'BEGIN {exit !(m > 8.5 || n < 90)}'; then echo "  REGRESSION: guard is ATE median <= 8.5 mm over >= 90 frames"; status=1; fi
# The tracker's quality signal as a failure detector: the quality alone at min_quality, and
# the tracker's rule (quality below min_quality, or free space above max_free_space).
quality_table=$($BIN eval tracking-quality --config robot_config/tracker.toml --dataset "$DATA/fr3_teddy_first200" \
  --camera robot_config/cameras/tum_fr3.toml)
q=$(echo "$quality_table" | grep "^| .*(min_quality)")
echo "tracking quality < min_quality as failure detector: $q"
if echo "$q" | awk -F'|' '{exit !($4 < 0.9 || $5 < 0.65)}'; then echo "  REGRESSION: guard is precision >= 0.9, recall >= 0.65"; status=1; fi
r=$(echo "$quality_table" | grep "^| .*(max_free_space)")
echo "the tracker's rule (quality, or free space above max_free_space) as failure detector: $r"
if echo "$r" | awk -F'|' '{exit !($4 < 0.9 || $5 < 0.8 || $7 > 0)}'; then
  echo "  REGRESSION: guard is precision >= 0.9, recall >= 0.8, no failure farther than 200 mm missed"; status=1
fi
python3 scripts/evo_crosscheck.py "$BIN" "$DATA/fr3_teddy_first200/groundtruth.txt" "$OUT/fr3_teddy_first200.txt"
echo "odometry step lengths against the ground truth, fr3_teddy_first200 (docs/evaluation.md):"
python3 scripts/step_lengths.py "$DATA/fr3_teddy_first200/groundtruth.txt" "$OUT/fr3_teddy_first200.txt" | sed 's/^/  /'
exit $status
