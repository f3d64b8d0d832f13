#!/usr/bin/env bash
# Instructions per frame of the per-frame step, by stage: the stable measure between
# versions on a shared machine whose clock varies (docs/benchmarks.md). Runs the release
# binary under callgrind on one thread and prints, per frame, the stages' instruction
# counts (inclusive: a stage counts all it calls).
#
#   scripts/profile.sh tracking [--qvga] [--frames N] [--first-frame F] [--against REV] [--keep FILE]
#   scripts/profile.sh odometry [--qvga] [--frames N] [--against REV] [--keep FILE]
#
# tracking: the teddy of robot_config/tracker.toml through fr3_teddy_first200 from frame
#   F (default 100), started at ground truth, N frames (default 30): scene map,
#   registration with the quality checks, and of that the quality score.
# odometry: the first N frames (default 21) of fr3_teddy_first200, each registered to
#   the previous one: map building per frame, registration per frame pair.
# --against REV: the same run of git revision REV too (built in a worktree under
#   target/profile-against/, removed at the end; the build is kept there for the next
#   comparison), side by side with this tree and the change in per cent: how a change
#   to the code is judged.
# --keep FILE: keep this tree's callgrind output (callgrind_annotate FILE shows it all).
#
# The release build splits the crate into four code-generation units, and which functions
# share a unit decides some of the compiler's inlining: a change in one module can move
# the counts of unchanged code elsewhere by up to ±1 %. To see a change's own effect,
# compare both builds with one unit: CARGO_PROFILE_RELEASE_CODEGEN_UNITS=1 before the
# command (each build then takes about 3.5 minutes instead of one).
#
# The camera's ray table, computed once when the first frame arrives (`RayTable::ensure`;
# the replay computes it before), is left out of the per-frame counts and printed apart.
#
# Needs valgrind (Debian: apt-get install valgrind) and ../shared/data/tum. Takes about
# 4 s per VGA frame and run. Counts of one build vary between runs by well under 0.1 %.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD

usage() {
    local text
    text=$(sed -n '2,31p' "$0" | sed 's/^# \{0,1\}//')
    if [[ ${1:-0} -eq 0 ]]; then echo "$text"; else echo "$text" >&2; fi
    exit "${1:-0}"
}
[[ $# -ge 1 ]] || usage 2
mode=$1
shift
case $mode in
    tracking | odometry) ;;
    -h | --help) usage 0 ;;
    *) echo "profile.sh: unknown mode '$mode' (tracking or odometry)" >&2; usage 2 ;;
esac
qvga=(); frames=""; first=100; keep=""; against=""
while [[ $# -gt 0 ]]; do
    case $1 in
        --qvga) qvga=(--qvga); shift ;;
        --frames) frames=${2:?--frames needs a number}; shift 2 ;;
        --first-frame) first=${2:?--first-frame needs a number}; shift 2 ;;
        --against) against=${2:?--against needs a git revision}; shift 2 ;;
        --keep) keep=${2:?--keep needs a file}; shift 2 ;;
        -h | --help) usage 0 ;;
        *) echo "profile.sh: unknown option '$1'" >&2; usage 2 ;;
    esac
done
if [[ $mode == tracking ]]; then frames=${frames:-30}; else frames=${frames:-21}; fi
# Odometry registers frame pairs: it needs two frames.
[[ $frames =~ ^[0-9]+$ && $frames -ge 1 && ($mode == tracking || $frames -ge 2) ]] ||
    { echo "profile.sh: --frames $frames: give a whole number of frames, at least $([[ $mode == tracking ]] && echo 1 || echo 2)" >&2; exit 2; }
[[ $first =~ ^[0-9]+$ ]] || { echo "profile.sh: --first-frame $first: give a frame index (0, 1, ...)" >&2; exit 2; }
size=VGA
[[ ${#qvga[@]} -eq 0 ]] || size=QVGA
for tool in valgrind callgrind_annotate; do
    command -v "$tool" > /dev/null || { echo "profile.sh: $tool not found (Debian: apt-get install valgrind)" >&2; exit 1; }
done
dataset=$root/../shared/data/tum/fr3_teddy_first200
[[ -d $dataset ]] || { echo "profile.sh: $dataset not found (the TUM data of ../shared)" >&2; exit 1; }
if [[ -n $against ]]; then
    rev=$(git rev-parse --verify --quiet "$against^{commit}") ||
        { echo "profile.sh: '$against' is not a git revision of this repository" >&2; exit 1; }
fi
work=$(mktemp -d)
against_tree=""
cleanup() {
    [[ -z $against_tree || ! -d $against_tree ]] || git worktree remove --force "$against_tree" || true
    rm -rf "$work"
}
trap cleanup EXIT

# Inclusive instructions in profile $1 of the function whose name ends in $2
# (callgrind_annotate lists a function once per file it has code from; the largest figure
# is the function's own; `--threshold=100` lists every function, as the default lists only
# the largest that make up 99 % of the total, and so not a small stage over many frames).
# A name not found (renamed in the code?) stops the script rather than count zero.
inclusive() {
    local count
    count=$(callgrind_annotate --inclusive=yes --threshold=100 "$1" 2> /dev/null |
        awk -v f="$2" '$0 ~ ("::" f "( \\[.*)?$") { gsub(",", "", $1); if ($1 + 0 > m) m = $1 + 0 } END { printf "%.0f\n", m }')
    if [[ $count == 0 ]]; then
        echo "profile.sh: no function named $2 in the profile $1 (renamed? update this script)" >&2
        exit 1
    fi
    echo "$count"
}
# $1 / $2 + $3 / $4 (instructions per frame).
per_frame() { awk -v a="$1" -v b="$2" -v c="${3:-0}" -v d="${4:-1}" 'BEGIN { printf "%.0f", a / b + c / d }'; }
# $1 - $2.
minus() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.0f", a - b }'; }

log=$work/log.txt
# The run under callgrind in tree $1 failed: its own messages, without valgrind's.
failed() {
    grep -v '^==[0-9]*==' "$log" >&2 || true
    echo "profile.sh: the run under callgrind failed (in $1)" >&2
    exit 1
}
# Frames the run processed, as its log says ("tracking N frames", "odometry N frames").
frames_run() {
    local count
    count=$(grep -oE "^$mode [0-9]+ frames" "$log" | awk '{ print $2 }')
    [[ ${count:-0} -gt 0 ]] || { echo "profile.sh: the run processed no frame (past the data's end?)" >&2; exit 1; }
    echo "$count"
}
# Runs the release binary of tree $1 under callgrind, its profile into $2, with the
# arguments that follow; its output goes to $log.
run_callgrind() {
    local dir=$1 out=$2
    shift 2
    (cd "$dir" && valgrind --tool=callgrind --callgrind-out-file="$out" ./target/release/mrsmap "$@") > "$log" 2>&1 ||
        failed "$dir"
}

# Profiles the tree $1 with its release binary into $2; prints "frames", "rays" and each
# stage's instructions per frame, one "name value" line each.
measure() {
    local dir=$1 out=$2 n rays
    if [[ $mode == tracking ]]; then
        # One thread; the model path made absolute, as the copy is elsewhere.
        sed -e 's/^# *threads = [0-9]*/threads = 1/' -e "s|\"\\.\\./models/|\"$dir/models/|" \
            "$dir/robot_config/tracker.toml" > "$work/tracker.toml"
        run_callgrind "$dir" "$out" track --config "$work/tracker.toml" --dataset "$dataset" \
            --camera robot_config/cameras/tum_fr3.toml --first-frame "$first" --max-frames "$frames" \
            --start-at-ground-truth "${qvga[@]}"
    else
        run_callgrind "$dir" "$out" odometry --dataset "$dataset" --camera robot_config/cameras/tum_fr3.toml \
            --out "$work/trajectory.txt" --threads 1 --max-frames "$frames" "${qvga[@]}"
    fi
    n=$(frames_run)
    # The first frame's ray table is start-up work (once per camera), not the step's.
    rays=$(inclusive "$out" RayTable::ensure)
    echo "frames $n"
    echo "rays $rays"
    if [[ $mode == tracking ]]; then
        local scene registration quality
        scene=$(minus "$(inclusive "$out" Tracker::build_scene)" "$rays")
        registration=$(inclusive "$out" Tracker::register_object)
        quality=$(inclusive "$out" MatchScratch::score)
        echo "step $(per_frame "$scene" "$n" "$registration" "$n")"
        echo "scene $(per_frame "$scene" "$n")"
        echo "registration $(per_frame "$registration" "$n")"
        echo "quality $(per_frame "$quality" "$n")"
    else
        local build registration
        build=$(minus "$(inclusive "$out" MapBuilder::build_region)" "$rays")
        registration=$(inclusive "$out" registration::register)
        echo "step $(per_frame "$build" "$n" "$registration" $((n - 1)))"
        echo "build $(per_frame "$build" "$n")"
        echo "registration $(per_frame "$registration" $((n - 1)))"
    fi
}

cargo build --release --quiet
if [[ -n $against ]]; then
    echo "profile.sh: building $against (${rev:0:10}) in a temporary worktree" >&2
    # At a fixed place, so that cargo rebuilds only what changed since the last comparison.
    against_tree=$root/target/profile-against/tree
    [[ ! -e $against_tree ]] || git worktree remove --force "$against_tree" 2> /dev/null || rm -rf "$against_tree"
    git worktree prune
    git worktree add --quiet --detach "$against_tree" "$rev"
    (cd "$against_tree" && CARGO_TARGET_DIR=$root/target/profile-against/build cargo build --release --quiet)
    mkdir -p "$against_tree/target/release"
    ln -s "$root/target/profile-against/build/release/mrsmap" "$against_tree/target/release/mrsmap"
    measure "$against_tree" "$work/against.out" > "$work/against.txt"
fi
measure "$root" "${keep:-$work/callgrind.out}" > "$work/this.txt"

value() { awk -v k="$1" '$1 == k { print $2 }' "$2"; }
n=$(value frames "$work/this.txt")
if [[ $mode == tracking ]]; then
    echo "tracking $size, teddy frames $first-$((first + n - 1)) ($n), one thread: instructions per frame"
    stages=(step "step (scene map + registration)" scene "scene map" registration "registration with the quality"
        quality "  of which the quality score")
else
    echo "odometry $size, teddy frames 0-$((n - 1)) ($n), one thread: instructions per frame (registration per pair)"
    stages=(step "map building + registration" build "map building" registration "registration")
fi
if [[ -n $against ]]; then
    printf "  %-33s %12s %12s %9s\n" "" "${against:0:12}" "this tree" "change"
    m=$(value frames "$work/against.txt")
    [[ $m == "$n" ]] || echo "  note: $against ran $m frames (a registration failed or the data differ), this tree $n"
fi
for ((i = 0; i < ${#stages[@]}; i += 2)); do
    now=$(value "${stages[i]}" "$work/this.txt")
    if [[ -n $against ]]; then
        then=$(value "${stages[i]}" "$work/against.txt")
        awk -v l="${stages[i + 1]}" -v a="$then" -v b="$now" \
            'BEGIN { printf "  %-33s %10.2f M %10.2f M %+8.2f %%\n", l, a / 1e6, b / 1e6, 100 * (b - a) / a }'
    else
        awk -v l="${stages[i + 1]}" -v b="$now" 'BEGIN { printf "  %-33s %10.2f M\n", l, b / 1e6 }'
    fi
done
awk -v r="$(value rays "$work/this.txt")" \
    'BEGIN { printf "  (left out: the camera ray table, once at the first frame: %.2f M)\n", r / 1e6 }'
[[ -z $keep ]] || echo "callgrind output: $keep (callgrind_annotate $keep)"
