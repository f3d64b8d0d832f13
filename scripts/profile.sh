#!/usr/bin/env bash
# Instructions per frame of the per-frame step, by stage: the stable measure between
# versions on a shared machine whose clock varies (docs/benchmarks.md). Runs the release
# binary under callgrind on one thread and prints, per frame, the stages' instruction
# counts (inclusive: a stage counts all it calls).
#
#   scripts/profile.sh tracking [--qvga] [--frames N] [--first-frame F] [--keep FILE]
#   scripts/profile.sh odometry [--qvga] [--frames N] [--keep FILE]
#
# tracking: the teddy of robot_config/tracker.toml through fr3_teddy_first200 from frame
#   F (default 100), started at ground truth, N frames (default 30): scene map,
#   registration with the quality checks, and of that the quality score.
# odometry: the first N frames (default 21) of fr3_teddy_first200, each registered to
#   the previous one: map building per frame, registration per frame pair.
#
# Needs valgrind (Debian: apt-get install valgrind) and ../shared/data/tum. Takes about
# 4 s per VGA frame. --keep FILE keeps the callgrind output (callgrind_annotate FILE
# shows every function). Counts of one build differ from run to run by well under 0.1 %.
set -euo pipefail
cd "$(dirname "$0")/.."

usage() {
    local text; text=$(sed -n "2,18p" "$0" | sed "s/^# \\{0,1\\}//")
    if [[ ${1:-0} -eq 0 ]]; then echo "$text"; else echo "$text" >&2; fi
    exit "${1:-0}"
}
[[ $# -ge 1 ]] || usage 2
mode=$1; shift
case $mode in tracking | odometry) ;; -h | --help) usage 0 ;; *) echo "profile.sh: unknown mode '$mode' (tracking or odometry)" >&2; usage 2 ;; esac
qvga=(); frames=""; first=100; keep=""
while [[ $# -gt 0 ]]; do
    case $1 in
        --qvga) qvga=(--qvga); shift ;;
        --frames) frames=${2:?--frames needs a number}; shift 2 ;;
        --first-frame) first=${2:?--first-frame needs a number}; shift 2 ;;
        --keep) keep=${2:?--keep needs a file}; shift 2 ;;
        -h | --help) usage 0 ;;
        *) echo "profile.sh: unknown option '$1'" >&2; usage 2 ;;
    esac
done
size=VGA
[[ ${#qvga[@]} -eq 0 ]] || size=QVGA
for tool in valgrind callgrind_annotate; do
    command -v "$tool" > /dev/null || { echo "profile.sh: $tool not found (Debian: apt-get install valgrind)" >&2; exit 1; }
done
dataset=../shared/data/tum/fr3_teddy_first200
[[ -d $dataset ]] || { echo "profile.sh: $dataset not found (the TUM data of ../shared)" >&2; exit 1; }
cargo build --release --quiet
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
out=${keep:-$work/callgrind.out}

# Inclusive instructions of the function whose name ends in $1 (callgrind_annotate lists a
# function once per file it has code from; the largest figure is the function's own).
# A name not found (renamed in the code?) stops the script rather than count zero.
inclusive() {
    local count
    count=$(callgrind_annotate --inclusive=yes "$out" 2> /dev/null |
        awk -v f="$1" '$0 ~ ("::" f "( \\[.*)?$") { gsub(",", "", $1); if ($1 + 0 > m) m = $1 + 0 } END { printf "%.0f\n", m }')
    if [[ $count == 0 ]]; then
        echo "profile.sh: no function named $1 in the profile (renamed? update this script)" >&2
        exit 1
    fi
    echo "$count"
}
per_frame() { awk -v n="$1" -v d="$2" 'BEGIN { printf "%7.2f M", n / d / 1e6 }'; }
# The sum of two per-frame figures.
per_frame2() { awk -v a="$1" -v b="$2" -v c="$3" -v d="$4" 'BEGIN { printf "%7.2f M", (a / b + c / d) / 1e6 }'; }

if [[ $mode == tracking ]]; then
    frames=${frames:-30}
    # One thread; the model path made absolute, as the copy is elsewhere.
    sed -e 's/^# *threads = [0-9]*/threads = 1/' -e "s|\"\\.\\./models/|\"$PWD/models/|" \
        robot_config/tracker.toml > "$work/tracker.toml"
    valgrind --tool=callgrind --callgrind-out-file="$out" ./target/release/mrsmap track \
        --config "$work/tracker.toml" --dataset "$dataset" --camera robot_config/cameras/tum_fr3.toml \
        --first-frame "$first" --max-frames "$frames" --start-at-ground-truth \
        --trajectory "$work/trajectory.txt" "${qvga[@]}" > "$work/log.txt" 2>&1 ||
        { cat "$work/log.txt" >&2; exit 1; }
    n=$(grep -cv '^#' "$work/trajectory.txt")
    scene=$(inclusive Tracker::build_scene)
    registration=$(inclusive Tracker::register_object)
    quality=$(inclusive MatchScratch::score)
    echo "tracking $size, teddy frames $first-$((first + n - 1)) ($n), one thread: instructions per frame"
    echo "  step (scene map + registration) $(per_frame2 "$scene" "$n" "$registration" "$n")"
    echo "  scene map                       $(per_frame "$scene" "$n")"
    echo "  registration with the quality   $(per_frame "$registration" "$n")"
    echo "    of which the quality score    $(per_frame "$quality" "$n")"
else
    frames=${frames:-21}
    valgrind --tool=callgrind --callgrind-out-file="$out" ./target/release/mrsmap odometry \
        --dataset "$dataset" --camera robot_config/cameras/tum_fr3.toml --out "$work/trajectory.txt" \
        --threads 1 --max-frames "$frames" "${qvga[@]}" > "$work/log.txt" 2>&1 ||
        { cat "$work/log.txt" >&2; exit 1; }
    n=$(grep -cv '^#' "$work/trajectory.txt")
    build=$(inclusive MapBuilder::build_region)
    registration=$(inclusive registration::register)
    echo "odometry $size, teddy frames 0-$((n - 1)) ($n), one thread: instructions per frame"
    echo "  map building + registration     $(per_frame2 "$build" "$n" "$registration" $((n - 1)))"
    echo "  map building                    $(per_frame "$build" "$n")"
    echo "  registration                    $(per_frame "$registration" $((n - 1)))"
fi
[[ -z $keep ]] || echo "callgrind output: $keep (callgrind_annotate $keep)"
