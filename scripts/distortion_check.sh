#!/usr/bin/env bash
# Lens distortion end to end, against OpenCV: fr3_teddy frames 100–199 are re-rendered by
# OpenCV as a wide rational-polynomial lens (8 coefficients, like an Azure Kinect's
# depth camera; up to 113 px of shift, 15 px median) by scripts/distort_dataset.py, then
# tracked twice: with the lens model in the camera file, and with the pinhole file that
# ignores it. Fails unless the run with the model tracks every frame at the tracking
# guard of scripts/accuracy.sh (ATE median <= 8.5 mm) and beats the run without it
# (docs/evaluation.md has the figures).
#
# Needs python3 with opencv-python-headless and numpy (installed here if missing).
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${MRSMAP_TUM:-../shared/data/tum}
BIN=target/release/mrsmap
[ -d "$DATA/fr3_teddy_first200" ] || { echo "distortion_check: $DATA/fr3_teddy_first200 not found (set MRSMAP_TUM)"; exit 1; }
python3 -c 'import cv2, numpy' 2>/dev/null ||
  python3 -m pip install --quiet --disable-pip-version-check 'opencv-python-headless==5.0.0.93' numpy >/dev/null
cargo build --release --quiet
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
python3 scripts/distort_dataset.py "$DATA/fr3_teddy_first200" "$OUT/teddy_rational" \
  --fx 535.4 --fy 539.2 --cx 320.1 --cy 247.6 \
  --distortion 3.2 1.9 0.0005 -0.0004 0.09 3.56 2.98 0.5 --first 100
# Tracks the distorted frames with camera file $1, prints the result labelled $2 and
# leaves the frames tracking in TRACKED, the ATE median (mm) in MEDIAN.
track() {
  local out line
  out=$($BIN track --config robot_config/tracker.toml --dataset "$OUT/teddy_rational" --camera "$1" \
    --start-at-ground-truth)
  line=$(echo "$out" | grep "ATE (aligned)" | sed -E 's/^ *camera position error vs ground truth //')
  TRACKED=$(echo "$out" | sed -nE 's/.* ([0-9]+) frames tracking \(([0-9]+) held\).*/\1 \2/p' | awk '{print $1 - $2}')
  MEDIAN=$(echo "$line" | sed -E 's/.*ATE \(aligned\) median ([0-9.]+) mm.*/\1/')
  printf 'distorted teddy 100-199, %-29s %s frames tracking, %s\n' "$2" "$TRACKED" "$line"
}
status=0
track "$OUT/teddy_rational/camera.toml" "rational_polynomial model:"
with_model=$MEDIAN
if awk -v m="$MEDIAN" -v n="$TRACKED" 'BEGIN {exit !(m > 8.5 || n < 93)}'; then
  echo "  REGRESSION: guard is ATE median <= 8.5 mm with all 93 frames tracking"; status=1
fi
track robot_config/cameras/tum_fr3.toml "lens ignored (pinhole file):"
if awk -v a="$with_model" -v b="$MEDIAN" 'BEGIN {exit !(a >= b)}'; then
  echo "  REGRESSION: the lens model does not help (ATE median $with_model mm with it, $MEDIAN mm without)"; status=1
fi
exit $status
