#!/usr/bin/env bash
# Live tracker benchmark: the camera driver, the tracker and the pose client as three
# processes, the shipped 8-frame clip played back and forth at 30 Hz (`--bounce`: a loop
# would jump back to the first pose every 8 frames) for N frames (default 600).
# Prints the tracker's time per frame and the latency from the driver's send to the
# pose's arrival at the client (median, p99). PIN=false runs the tracker with its worker
# threads unpinned (`pin_threads` in robot_config/tracker.toml).
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
QVGA=""; [ "$SIZE" = qvga ] && QVGA="--qvga"
$BIN track --config "$OUT/tracker.toml" --max-frames "$N" > "$OUT/tracker.txt" 2> "$OUT/tracker.err" &
TRACKER=$!
until grep -q ready "$OUT/tracker.err" 2>/dev/null; do sleep 0.1; done
$BIN poses --service "$TAG/poses" --quiet --count "$N" --timeout 30 > "$OUT/poses.txt" 2>/dev/null &
CLIENT=$!
sleep 0.5
$BIN camera --dataset tests/data/fr3_teddy_8 --camera robot_config/cameras/tum_fr3.toml \
  --service "$TAG/camera" --bounce --rate "${RATE:-30}" $QVGA 2>/dev/null &
wait $TRACKER
wait $CLIENT || true
echo "live tracker, $SIZE, $N frames at ${RATE:-30} Hz ($(nproc) cores, $(date -u +%F)):"
grep -o "on [0-9]* thread(s) ([^)]*)" "$OUT/tracker.err" || true
cat "$OUT/tracker.txt" "$OUT/poses.txt"
