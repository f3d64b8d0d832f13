#!/usr/bin/env bash
# Live tracker benchmark: the camera driver, the tracker and the pose client as three
# processes, the shipped 8-frame clip played back and forth at 30 Hz (`--bounce`: a loop
# would jump back to the first pose every 8 frames) for N frames (default 600).
# Prints the tracker's time per frame and the latency from the driver's send to the
# pose's arrival at the client (median, p99). PIN=false runs the tracker with its worker
# threads unpinned (`pin_threads` in robot_config/tracker.toml). DATASET=DIR plays another
# TUM folder (CAMERA=FILE: its camera file, default robot_config/cameras/tum_fr3.toml),
# and OBJECTS=FILE (a file of [[object]] tables, model paths absolute) tracks its objects
# instead of the teddy: e.g. the rendered cow of scripts/synthetic_objects.sh
# (docs/benchmarks-history.md, "Live: camera driver → tracker → client", stop 74).
set -euo pipefail
cd "$(dirname "$0")/.."
N=${1:-600}
SIZE=${2:-vga}
BIN=target/release/mrsmap
cargo build --release --quiet
OUT=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$OUT"' EXIT
TAG="mrsmap_bench_$$"
sed -e "s#^service = \"mrsmap/camera0\"#service = \"$TAG/camera\"#" \
    -e "s#^service = \"mrsmap/poses\"#service = \"$TAG/poses\"#" \
    -e "s#^service = \"mrsmap/detections\"#service = \"$TAG/detections\"#" \
    -e "s#^size = \"vga\"#size = \"$SIZE\"#" \
    -e "s#^pin_threads = true #pin_threads = ${PIN:-true} #" \
    -e "s#\"\.\./models/#\"$PWD/models/#" robot_config/tracker.toml > "$OUT/tracker.toml"
if [ -n "${OBJECTS:-}" ]; then
    [ -f "$OBJECTS" ] || { echo "bench_live: OBJECTS=$OBJECTS: no such file" >&2; exit 2; }
    # The configuration up to its objects, then those of the file.
    sed -i '/^\[\[object\]\]/,$d' "$OUT/tracker.toml"
    cat "$OBJECTS" >> "$OUT/tracker.toml"
fi
DATASET=${DATASET:-tests/data/fr3_teddy_8}
[ -d "$DATASET" ] || { echo "bench_live: DATASET=$DATASET: no such folder" >&2; exit 2; }
CAMERA=${CAMERA:-robot_config/cameras/tum_fr3.toml}
[ -f "$CAMERA" ] || { echo "bench_live: CAMERA=$CAMERA: no such file" >&2; exit 2; }
QVGA=""; [ "$SIZE" = qvga ] && QVGA="--qvga"
$BIN track --config "$OUT/tracker.toml" --max-frames "$N" > "$OUT/tracker.txt" 2> "$OUT/tracker.err" &
TRACKER=$!
until grep -q ready "$OUT/tracker.err" 2>/dev/null; do
    kill -0 $TRACKER 2>/dev/null || { cat "$OUT/tracker.err" >&2; echo "bench_live: the tracker did not start" >&2; exit 1; }
    sleep 0.1
done
$BIN poses --service "$TAG/poses" --quiet --count "$N" --timeout 30 > "$OUT/poses.txt" 2>/dev/null &
CLIENT=$!
sleep 0.5
$BIN camera --dataset "$DATASET" --camera "$CAMERA" \
  --service "$TAG/camera" --bounce --rate "${RATE:-30}" $QVGA 2>/dev/null &
wait $TRACKER
wait $CLIENT || true
echo "live tracker, $SIZE, $N frames of $DATASET at ${RATE:-30} Hz ($(nproc) cores, $(date -u +%F)):"
grep -o "on [0-9]* thread(s) ([^)]*)" "$OUT/tracker.err" || true
cat "$OUT/tracker.txt" "$OUT/poses.txt"
