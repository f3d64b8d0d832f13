#!/usr/bin/env bash
# mrsmap on an ARM robot computer (aarch64: NVIDIA Jetson, Raspberry Pi 5, an ARM server):
# cross-builds the release binary for aarch64-unknown-linux-gnu, runs it under qemu-user
# emulation, and checks that it computes the same results, bit for bit, as this machine's
# x86-64 build:
#   - odometry on fr1_xyz (37 frames) and fr3_teddy (193 frames, QVGA): the trajectories;
#   - the mapping tool learning the teddy model from frames 0-99: the model file and the
#     key views' trajectory;
#   - the tracker step on frames 100-199 (VGA): the trajectory;
#   - where binfmt_misc can run aarch64 programs, `mrsmap demo`: the camera driver and the
#     tracker as two aarch64 processes over iceoryx2 shared memory, their poses.
# Emulation says nothing about speed on a real ARM core (docs/benchmarks.md, "Building for
# the robot's CPU").
#
# Installs what it lacks where it can: the Rust target (rustup) and, as root on Debian,
# gcc-aarch64-linux-gnu, libc6-dev-arm64-cross and qemu-user. Where these cannot be
# installed it says so and exits 0 with MRSMAP_AARCH64_OPTIONAL=1 (else 1); a difference
# always fails. Takes about 6 minutes on 2 cores (the cross build 4, the emulated runs 2).
#   scripts/aarch64_check.sh            # data in ../shared/data/tum (MRSMAP_TUM=DIR to change)
set -euo pipefail
cd "$(dirname "$0")/.."
TARGET=aarch64-unknown-linux-gnu
DATA=${MRSMAP_TUM:-../shared/data/tum}
[ -d "$DATA" ] || { echo "aarch64_check: $DATA not found (set MRSMAP_TUM)" >&2; exit 1; }
not_run() {
    echo "aarch64_check: NOT RUN: $1" >&2
    [ "${MRSMAP_AARCH64_OPTIONAL:-0}" = 1 ] && exit 0
    exit 1
}

# What the cross build and the emulation need.
if ! rustup target list --installed 2>/dev/null | grep -qx "$TARGET"; then
    rustup target add "$TARGET" > /dev/null 2>&1 || not_run "the Rust target $TARGET could not be installed (rustup target add)"
fi
if ! command -v aarch64-linux-gnu-gcc > /dev/null || ! command -v qemu-aarch64 > /dev/null; then
    [ "$(id -u)" = 0 ] && command -v apt-get > /dev/null \
        || not_run "aarch64-linux-gnu-gcc and qemu-aarch64 are missing (Debian: gcc-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user)"
    apt-get update -qq > /dev/null 2>&1 || true
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq gcc-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user \
        > /dev/null 2>&1 || not_run "apt-get could not install the cross compiler and qemu-user"
fi
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
# Where the emulator finds the aarch64 dynamic loader and libc (also for programs that
# binfmt_misc starts).
export QEMU_LD_PREFIX=/usr/aarch64-linux-gnu

echo "aarch64_check: building (x86-64, then $TARGET)"
cargo build --release --quiet
cargo build --release --quiet --target "$TARGET"
X86=target/release/mrsmap
ARM=target/$TARGET/release/mrsmap
if command -v file > /dev/null && ! file "$ARM" | grep -q "ARM aarch64"; then
    echo "aarch64_check: $ARM is not an aarch64 program" >&2
    exit 1
fi
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
status=0

# Runs `mrsmap ARGS` with both binaries (the aarch64 one emulated), each writing its
# files into its own folder (the argument @OUT@ names it), and compares the files listed
# in $FILES byte for byte.
both() {
    local name=$1; shift
    for arch in x86 arm; do
        mkdir -p "$OUT/$arch"
        local bin=$X86 runner=()
        [ $arch = arm ] && bin=$ARM && runner=(qemu-aarch64)
        local args=("${@//@OUT@/$OUT/$arch}")
        local start=$SECONDS
        "${runner[@]}" "$bin" "${args[@]}" > "$OUT/$arch.log" 2>&1 \
            || { cat "$OUT/$arch.log"; echo "aarch64_check: $name failed on $arch" >&2; exit 1; }
        [ $arch = arm ] && arm_secs=$((SECONDS - start))
    done
    local verdict="identical"
    for f in $FILES; do
        cmp -s "$OUT/x86/$f" "$OUT/arm/$f" || { verdict="DIFFERENT ($f)"; status=1; }
    done
    printf '  %-52s %s (emulated in %d s)\n' "$name" "$verdict" "$arm_secs"
}

echo "aarch64_check: the aarch64 build against the x86-64 build, bit for bit"
FILES="xyz.txt" both "odometry fr1_xyz, VGA" odometry --dataset "$DATA/fr1_xyz_first37" \
    --camera robot_config/cameras/tum_fr1.toml --out @OUT@/xyz.txt
FILES="teddy_qvga.txt" both "odometry fr3_teddy, QVGA" odometry --dataset "$DATA/fr3_teddy_first200" \
    --camera robot_config/cameras/tum_fr3.toml --qvga --out @OUT@/teddy_qvga.txt
FILES="teddy.mrsm slam.txt" both "mapping tool: the teddy model from frames 0-99" map \
    --dataset "$DATA/fr3_teddy_first200" --camera robot_config/cameras/tum_fr3.toml \
    --object robot_config/objects/teddy.toml --max-frames 100 --out @OUT@/teddy.mrsm --trajectory @OUT@/slam.txt
FILES="track.txt" both "tracker step, frames 100-199, VGA" track --config robot_config/tracker.toml \
    --dataset "$DATA/fr3_teddy_first200" --camera robot_config/cameras/tum_fr3.toml --first-frame 100 \
    --start-at-ground-truth --trajectory @OUT@/track.txt

# The demo starts its camera driver and tracker as programs of their own (the running
# binary): an aarch64 binary runs them only where binfmt_misc hands aarch64 programs to
# qemu. Registering it needs root and changes the machine until it restarts.
binfmt=/proc/sys/fs/binfmt_misc
if [ ! -e $binfmt/qemu-aarch64 ] && [ "$(id -u)" = 0 ] && [ -f /usr/lib/binfmt.d/qemu-aarch64.conf ]; then
    [ -e $binfmt/register ] || mount -t binfmt_misc binfmt_misc $binfmt 2> /dev/null || true
    [ -e $binfmt/register ] && cat /usr/lib/binfmt.d/qemu-aarch64.conf > $binfmt/register 2> /dev/null || true
fi
if [ -e $binfmt/qemu-aarch64 ] && grep -q enabled $binfmt/qemu-aarch64; then
    # One frame a second: the emulated tracker (80-100 ms a frame, the first up to ~300 ms
    # on a busy machine) takes every frame, and a skipped one would change the poses.
    for arch in x86 arm; do
        bin=$X86; [ $arch = arm ] && bin=$ARM
        "$bin" demo --rate 1 > "$OUT/demo_$arch.log" 2>&1 \
            || { cat "$OUT/demo_$arch.log"; echo "aarch64_check: the demo failed on $arch" >&2; exit 1; }
        # The poses (stamp, status, position, quality, free space, error), not the times.
        grep -E '^[0-9]{10}\.' "$OUT/demo_$arch.log" | awk '{print $1, $2, $3, $4, $5, $6, $7, $9}' > "$OUT/demo_$arch.txt"
    done
    poses=$(wc -l < "$OUT/demo_arm.txt")
    verdict="identical ($poses poses)"
    { [ "$poses" -gt 0 ] && cmp -s "$OUT/demo_x86.txt" "$OUT/demo_arm.txt"; } || { verdict="DIFFERENT"; status=1; }
    printf '  %-52s %s\n' "demo: driver and tracker, two aarch64 processes" "$verdict"
    grep -E "tracking .* per frame \(median\)" "$OUT/demo_arm.log" | sed 's/^ */    emulated: /'
else
    echo "  demo: not run (binfmt_misc cannot start aarch64 programs here: needs root and qemu-user)"
fi
[ $status = 0 ] && echo "aarch64_check: passed" || echo "aarch64_check: FAILED: the aarch64 build computes other results"
exit $status
