#!/usr/bin/env bash
# Interop with an independent implementation: a camera driver and pose reader written in
# Python against docs/wire-format.md (iceoryx2 from PyPI) drives `mrsmap track`, and sends
# it a detection that re-initialises the object.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip install --quiet --disable-pip-version-check 'iceoryx2==0.10.0' numpy pillow >/dev/null 2>&1
cargo build --release --quiet
OUT=$(mktemp -d)
TAG="mrsmap_py_$$"
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$OUT"' EXIT
sed -e "s#^service = \"mrsmap/camera0\"#service = \"$TAG/camera\"#" \
    -e "s#^service = \"mrsmap/poses\"#service = \"$TAG/poses\"#" \
    -e "s#^service = \"mrsmap/detections\"#service = \"$TAG/detections\"#" \
    -e "s#\"\.\./models/#\"$PWD/models/#" robot_config/tracker.toml > "$OUT/tracker.toml"
target/release/mrsmap track --config "$OUT/tracker.toml" --idle-timeout 20 > "$OUT/tracker.txt" 2> "$OUT/tracker.err" &
until grep -q ready "$OUT/tracker.err" 2>/dev/null; do sleep 0.1; done
IOX2_LOG_LEVEL=Error python3 scripts/python_driver.py tests/data/fr3_teddy_8 --service "$TAG/camera" --poses "$TAG/poses" \
    --detections "$TAG/detections"
grep -q "'teddy' re-initialised at a detection (mode always)" "$OUT/tracker.err" \
    || { echo "the tracker did not take the Python detection:"; cat "$OUT/tracker.err"; exit 1; }

# MCAP: what mrsmap writes, read by the Python mcap readers with their ROS 2 and protobuf
# decoders (the other direction, Python-written files read by mrsmap, is in
# tests/mcap_replay.rs with the fixtures of scripts/make_mcap_fixture.py).
python3 -m pip install --quiet --disable-pip-version-check 'mcap==1.6.0' 'mcap-ros2-support==0.6.0' \
    'mcap-protobuf-support==0.6.0' 'foxglove-schemas-protobuf==0.4.0' >/dev/null 2>&1
target/release/mrsmap convert tum-to-mcap tests/data/fr3_teddy_8 --out "$OUT/teddy.mcap"
target/release/mrsmap replay --input "$OUT/teddy.mcap" --config robot_config/tracker.toml \
    --out "$OUT/poses.mcap" --trajectory "$OUT/poses.txt"
python3 scripts/mcap_interop.py tests/data/fr3_teddy_8 robot_config/cameras/tum_fr3.toml \
    "$OUT/teddy.mcap" "$OUT/poses.mcap" "$OUT/poses.txt"
