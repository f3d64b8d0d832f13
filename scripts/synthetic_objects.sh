#!/usr/bin/env bash
# The tracker on manipulation-sized objects with exact ground truth: a table with five
# textured meshes (scripts/scenes/ycb_table.toml: the YCB banana and scissors, a drink
# bottle, a cow, Suzanne; meshes from ../shared/data/meshes) rendered through a model of
# a Kinect (`mrsmap synth`). For each object the mapping tool learns a model from the
# `model` orbit; all five are then tracked together, in one tracker, along the held-out
# `track` path (another height, approaches to 0.45 m, faster turns, more shake), started
# at the ground truth. Then the tracker's failure detection is measured per object on
# the same held-out frames (`mrsmap eval tracking-quality`), as for the teddy.
#
# Prints a table per object; fails on a regression beyond the guard values below
# (docs/evaluation.md, "Objects a gripper picks up"), not on the figures themselves.
#   scripts/synthetic_objects.sh [WORKDIR]   (default: a temporary folder, removed)
set -euo pipefail
cd "$(dirname "$0")/.."
MESHES=../shared/data/meshes
[ -d "$MESHES" ] || { echo "synthetic_objects: $MESHES not found"; exit 1; }
BIN=target/release/mrsmap
CAMERA=robot_config/cameras/tum_fr3.toml
SCENE=scripts/scenes/ycb_table.toml
cargo build --release --quiet
if [ $# -ge 1 ]; then OUT=$1; mkdir -p "$OUT"; else OUT=$(mktemp -d); trap 'rm -rf "$OUT"' EXIT; fi
status=0

$BIN synth --scene "$SCENE" --out "$OUT" --force
frames=$(grep -vc '^#' "$OUT/track/associations.txt")

# Models: one SLAM run of the model orbit per object (its volume of interest).
echo "models from the model orbit:"
objects="banana scissors bottle cow monkey"
config="$OUT/tracker.toml"
printf '[camera]\nservice = "mrsmap/synthetic"\n' > "$config"
for o in $objects; do
  $BIN map --dataset "$OUT/model" --camera $CAMERA --object "scripts/scenes/ycb_table/$o.toml" \
    --out "$OUT/$o.mrsm" --force > "$OUT/map_$o.log" 2>&1 || { cat "$OUT/map_$o.log"; exit 1; }
  printf "  %-9s %s\n" "$o" "$(sed -nE 's/.*model .* \(object frame\): [0-9]+ nodes, ([0-9]+ surfels), usable surfels per level \(finest first\) (\[[0-9, ]*\]).*/\1 (usable per level \2)/p' "$OUT/map_$o.log")"
  # The configured pose is never used: every run starts at the ground truth.
  object=$(printf '[[object]]\nname = "%s"\nmodel = "%s.mrsm"\ncamera_from_object = [0, 0, 1, 0, 0, 0, 1]\n' "$o" "$o")
  echo "$object" >> "$config"
  printf '[camera]\nservice = "mrsmap/synthetic"\n%s\n' "$object" > "$OUT/only_$o.toml"
done
echo "  (SLAM $(grep -o 'ATE vs ground truth.*' "$OUT/map_banana.log" | sed 's/ vs ground truth//'))"

# All five in one tracker along the held-out path: once on its own from the ground-truth
# start (a lost object is searched for around its last and its configured pose), once
# with every lost object re-initialised at the ground truth, as a perfect detector would.
$BIN track --config "$config" --dataset "$OUT/track" --camera $CAMERA --start-at-ground-truth \
  > "$OUT/alone.log" 2>&1 || { cat "$OUT/alone.log"; exit 1; }
$BIN track --config "$config" --dataset "$OUT/track" --camera $CAMERA --reinitialise-at-ground-truth \
  --trajectory "$OUT/tracked.txt" > "$OUT/track.log" 2>&1 || { cat "$OUT/track.log"; exit 1; }
echo
echo "held-out path, $frames frames, all objects in one tracker:"
# Guards (regressions, not targets; measured 2026-12-04, docs/evaluation.md): frames
# estimated at least. The banana is never found from the start. The cow and Suzanne are
# kept because a small object's scene map is all on one level (`small_objects_on_one_level`;
# without it 35 and 0 frames); the others are found again after a loss because a lost
# object follows the camera motion the tracked ones measure (`follow_tracked_objects`,
# only from an object whose registration fixes its rotation: not the bottle's turn).
while read -r o min_alone; do
  counts=$(sed -nE "s/^$o: ([0-9]+) frames tracking \(([0-9]+) held\), ([0-9]+) lost.*/\1 \2 \3/p" "$OUT/alone.log")
  read -r tracking held lost <<< "$counts"
  printf '  %-9s on its own: estimated %3d of %d frames (%d held, %d lost)\n' "$o" "$((tracking - held))" "$frames" "$held" "$lost"
  if [ "$((tracking - held))" -lt "$min_alone" ]; then
    echo "    REGRESSION: guard is >= $min_alone frames estimated on its own"
    status=1
  fi
done <<'TABLE'
banana   0
scissors 60
bottle   190
cow      240
monkey   60
TABLE
echo "  with a perfect detector after each loss:"
# Guards (regressions, not targets: measured 2026-12-01, the cow's and Suzanne's 2026-12-04;
# recorded in docs/evaluation.md):
# frames estimated at least, ATE median at most (mm; the bottle's turn about its axis
# is free, so its ATE is not guarded), precision and recall at least, gross failures
# (> 200 mm) accepted at most. The perturbed starts: 8 per frame. The gross failures
# accepted are rare events: with 2 starts per frame (until 2026-12-07) their count was
# a coin flip (stop 83's build: Suzanne 2-16 over seeds 1-8 against a limit of 3). Their
# limits are the worst count of seeds 1-8 with stop 83's build at 8 starts per frame
# (docs/evaluation.md, "Objects a gripper picks up").
while read -r o min_fresh max_ate min_precision min_recall max_gross; do
  block=$(sed -n "/^$o:/,/^[a-z]*:/p" "$OUT/track.log")
  counts=$(echo "$block" | sed -nE "s/^$o: ([0-9]+) frames tracking \(([0-9]+) held\), ([0-9]+) lost, ([0-9]+) initialising.*/\1 \2 \3 \4/p")
  read -r tracking held lost init <<< "$counts"
  fresh=$((tracking - held))
  ate=$(echo "$block" | sed -nE 's/.*ATE \(aligned\) median ([0-9.]+) mm, max ([0-9.]+) mm.*/\1 \2/p')
  read -r ate_median ate_max <<< "${ate:-nan nan}"
  reinit=$(echo "$block" | sed -nE 's/.*re-initialised at the ground truth before ([0-9]+) frames.*/\1/p')
  if [ "$fresh" -ge 3 ]; then
    quality=$($BIN eval tracking-quality --config "$OUT/only_$o.toml" --dataset "$OUT/track" --camera $CAMERA \
      --first-frame 0 --frames "$frames" --trials 8 2>&1) || quality="error: $quality"
    rule=$(echo "$quality" | { grep '(max_free_space)' || true; } | awk -F'|' '{print $4, $5, $7}')
    trials=$(echo "$quality" | sed -nE 's/^([0-9]+) registrations from priors.* ([0-9]+) failed .*/\2 of \1 failed/p')
  else
    rule="nan nan nan"; trials="none"
  fi
  read -r precision recall gross <<< "${rule:-nan nan nan}"
  printf '  %-9s estimated %3d of %d frames (%d held, %d lost, %d initialising, %3d re-initialised), ATE median %5s max %5s mm;\n              failure detection from perturbed priors (%s): precision %s recall %s, gross failures accepted %s\n' \
    "$o" "$fresh" "$frames" "$held" "$lost" "$init" "${reinit:-0}" "$ate_median" "$ate_max" "$trials" "$precision" "$recall" "$gross"
  if awk -v f="$fresh" -v a="$ate_median" -v p="$precision" -v r="$recall" -v g="$gross" \
    -v mf="$min_fresh" -v ma="$max_ate" -v mp="$min_precision" -v mr="$min_recall" -v mg="$max_gross" \
    'BEGIN { bad = f < mf; if (ma != "-") bad = bad || a == "nan" || a > ma;
             if (mp != "-") bad = bad || p == "nan" || p < mp || r < mr || g > mg; exit !bad }'; then
    echo "    REGRESSION: guard is >= $min_fresh frames estimated, ATE median <= $max_ate mm, precision >= $min_precision, recall >= $min_recall, gross accepted <= $max_gross"
    status=1
  fi
done <<'TABLE'
banana   140 25  0.9 0.9  0
scissors 130 15  0.9 0.9  1
bottle   200 -   0.9 0.9  9
cow      250 8   0.9 0.85 5
monkey   65  12  0.9 0.85 20
TABLE

# The colour term (`color_term = true` on the object; not in the paper): the bottle's
# label holds its turn about its axis, which its shape leaves free. Guards measured
# 2026-12-04 (docs/evaluation.md, "The colour term"): without it 80 frames estimated
# on its own and ATE median 67.0 mm with the perfect detector.
echo "  the bottle with the colour term:"
printf 'color_term = true\n' | cat "$OUT/only_bottle.toml" - > "$OUT/color_bottle.toml"
alone=$($BIN track --config "$OUT/color_bottle.toml" --dataset "$OUT/track" --camera $CAMERA --start-at-ground-truth 2>&1) \
  || { echo "$alone"; exit 1; }
fresh=$($BIN track --config "$OUT/color_bottle.toml" --dataset "$OUT/track" --camera $CAMERA \
  --reinitialise-at-ground-truth 2>&1) || { echo "$fresh"; exit 1; }
alone_n=$(echo "$alone" | sed -nE 's/^bottle: ([0-9]+) frames tracking \(([0-9]+) held\).*/\1 \2/p' | awk '{print $1 - $2}')
ate=$(echo "$fresh" | sed -nE 's/.*\(([0-9]+) frames\): ATE \(aligned\) median ([0-9.]+) mm, max ([0-9.]+) mm.*/\1 \2 \3/p')
read -r fresh_n ate_median ate_max <<< "${ate:-0 nan nan}"
printf '  %-9s on its own: estimated %3d of %d frames; with a perfect detector %3d frames, ATE median %5s max %5s mm\n' \
  bottle "$alone_n" "$frames" "$fresh_n" "$ate_median" "$ate_max"
if awk -v a="$alone_n" -v f="$fresh_n" -v m="$ate_median" 'BEGIN { exit !(a < 240 || f < 250 || m == "nan" || m > 25) }'; then
  echo "    REGRESSION: guard is >= 240 frames on its own, >= 250 with the detector, ATE median <= 25 mm"
  status=1
fi

# QVGA (images halved on load): the scene map's surfels need 5 points there instead of
# the paper's 10 (`scene_min_points_by_image_size`). Guards measured 2026-12-04
# (docs/evaluation.md, "Small objects at QVGA"): without it the cow was estimated in 40
# frames on its own, the bottle in 34, Suzanne in none.
echo "  at QVGA, all objects in one tracker, on their own:"
qvga=$($BIN track --config "$config" --dataset "$OUT/track" --camera $CAMERA --start-at-ground-truth --qvga 2>&1) \
  || { echo "$qvga"; exit 1; }
while read -r o min_alone; do
  n=$(echo "$qvga" | sed -nE "s/^$o: ([0-9]+) frames tracking \(([0-9]+) held\).*/\1 \2/p" | awk '{print $1 - $2}')
  printf '  %-9s estimated %3d of %d frames\n' "$o" "${n:-0}" "$frames"
  if [ "${n:-0}" -lt "$min_alone" ]; then
    echo "    REGRESSION: guard is >= $min_alone frames estimated on its own at QVGA"
    status=1
  fi
done <<'TABLE'
bottle   170
cow      240
monkey   65
TABLE
exit $status
