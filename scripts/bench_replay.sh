#!/usr/bin/env bash
# Replay throughput, end to end (reading, decoding, tracking one object, writing poses):
# fr3_teddy_first200 frames 100-199 as a VGA ROS 2 recording (16UC1 depth, zstd), replayed
# three times at 2 and at 1 worker threads, and three times at 2 threads with 4 MiB chunks
# (three frames per chunk, as `ros2 bag record`'s zstd_small preset writes; the default
# holds one frame per chunk); also reading + decoding alone (--every with a huge step
# decodes every frame and tracks only the first). Prints Markdown rows, then how fast one
# core ran `mrsmap bench`'s probe loop before and after (a slowed host shows there).
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${DATA:-../shared/data/tum/fr3_teddy_first200}
cargo build --release --quiet
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
B=target/release/mrsmap
$B convert tum-to-mcap "$DATA" --first-frame 100 --out "$OUT/rec.mcap" >/dev/null
$B convert tum-to-mcap "$DATA" --first-frame 100 --chunk-size 4194304 --out "$OUT/rec4m.mcap" >/dev/null
probe() {
    $B bench --dataset tests/data/fr3_teddy_8 --camera robot_config/cameras/tum_fr3.toml --frames 2 --passes 1 \
        --resolution qvga --graph-key-views 0 | sed -n 's/.*one thread ran it in \([0-9.]*\) ms before.*/\1/p'
}
probe_before=$(probe)
echo "| run | threads | frames/s end to end | after the first frame | tracking median ms | peak RSS MB |"
echo "|---|---|---|---|---|---|"
for setting in "2 rec" "1 rec" "2 rec4m"; do
    read -r threads rec <<< "$setting"
    sed -e "s/^# threads = 2 /threads = $threads #/" -e "s#\"\.\./models/#\"$PWD/models/#" \
        robot_config/tracker.toml > "$OUT/tracker.toml"
    label=replay
    [ "$rec" = rec4m ] && label="replay, 4 MiB chunks"
    for run in 1 2 3; do
        /usr/bin/time -f "%M" -o "$OUT/rss" $B replay --input "$OUT/$rec.mcap" --config "$OUT/tracker.toml" \
            --out "$OUT/poses.mcap" --force > "$OUT/log"
        fps=$(sed -n 's/.* s, \([0-9.]*\) frames\/s.*/\1/p' "$OUT/log")
        steady=$(sed -n 's/.*after the first frame: \([0-9.]*\) frames\/s.*/\1/p' "$OUT/log")
        med=$(sed -n 's/.*median \([0-9.]*\) ms.*/\1/p' "$OUT/log")
        echo "| $label $run | $threads | $fps | $steady | $med | $(( $(cat "$OUT/rss") / 1024 )) |"
    done
done
start=$(date +%s.%N)
/usr/bin/time -f "%M" -o "$OUT/rss" $B replay --input "$OUT/rec.mcap" --config "$OUT/tracker.toml" --every 1000000 >/dev/null
end=$(date +%s.%N)
frames=$(python3 -c "print(len([l for l in open('$DATA/associations.txt') if l.strip() and not l.startswith('#')]) - 100)")
echo "| read + decode only (process start and model load included) | - | $(python3 -c "print(round($frames / ($end - $start), 1))") | - | - | $(( $(cat "$OUT/rss") / 1024 )) |"
echo
echo "probe loop on one core: $probe_before ms before, $(probe) ms after (docs/benchmarks.md: this machine's quiet figure)"
