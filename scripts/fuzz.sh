#!/usr/bin/env bash
# Fuzzes mrsmap's inputs with cargo-fuzz (libFuzzer + AddressSanitizer); docs/fuzzing.md.
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]   fuzz each target for SECONDS (default 60)
#   scripts/fuzz.sh --smoke [TARGET...]     CI: a fixed-seed run of 2000 inputs per target,
#                                           after replaying the seeds and every input in
#                                           fuzz/regressions/TARGET (the same inputs on every
#                                           run, except where rayon's thread timing changes
#                                           the coverage tracker_frame sees)
#
# Targets: model_file mcap_recording image_message text_inputs tracker_frame (default: all).
# Needs the nightly toolchain (cargo-fuzz 0.13.2 is installed if missing). A crash stops
# the script with a non-zero status; the input is in fuzz/artifacts/TARGET/.
set -euo pipefail
cd "$(dirname "$0")/.."

ALL=(model_file mcap_recording image_message text_inputs tracker_frame)
mode=fuzz
seconds=60
if [[ "${1:-}" == "--smoke" ]]; then mode=smoke; shift
elif [[ "${1:-}" =~ ^[0-9]+$ ]]; then seconds=$1; shift
elif [[ "${1:-}" == -h || "${1:-}" == --help ]]; then sed -n 2,13p "$0"; exit 0
fi
targets=("$@")
[[ ${#targets[@]} -eq 0 ]] && targets=("${ALL[@]}")

if ! rustup run nightly rustc --version >/dev/null 2>&1; then
    echo "fuzz.sh: the nightly toolchain is needed (rustup toolchain install nightly)" >&2
    exit 1
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz.sh: installing cargo-fuzz 0.13.2" >&2
    cargo install --quiet --locked cargo-fuzz@0.13.2
fi

# Inputs that once crashed a target (and now must not), and the committed seeds.
inputs() {
    local dirs=()
    for d in "fuzz/seeds/$1" "fuzz/regressions/$1"; do [[ -d $d ]] && dirs+=("$d"); done
    echo "${dirs[@]:-}"
}

cargo +nightly fuzz build
mkdir -p fuzz/logs
# The targets write their scratch files (one set per process) under TMPDIR: a folder of
# this run's, removed at the end.
scratch=$(mktemp -d -t mrsmap-fuzz-scratch.XXXXXX)
trap 'rm -rf "$scratch"' EXIT
export TMPDIR=$scratch
# Runs libFuzzer; on a failure shows the end of its log (the panic and the input's path).
run() {
    local t=$1 log="fuzz/logs/$1.log"; shift
    if ! cargo +nightly fuzz run "$t" "$@" >"$log" 2>&1; then
        tail -n 40 "$log" >&2
        echo "fuzz.sh: $t failed; log: $log, inputs: fuzz/artifacts/$t/" >&2
        exit 1
    fi
    grep -E '^Done|^#[0-9]+.*DONE' "$log" | tail -n 1
}
# -malloc_limit_mb: the `mcap` crate reserves a string of the length a record claims (u32:
# up to 4 GiB, virtual, never touched) before it finds the record too short; see
# docs/fuzzing.md. Resident memory stays limited to 2 GiB.
limits=(-timeout=20 -rss_limit_mb=2048 -malloc_limit_mb=4608 -max_len=1048576)
for t in "${targets[@]}"; do
    mkdir -p "fuzz/corpus/$t"
    read -r -a extra <<<"$(inputs "$t")"
    dict=()
    [[ -f fuzz/dict/$t.dict ]] && dict=(-dict="fuzz/dict/$t.dict")
    if [[ $mode == smoke ]]; then
        echo "== $t: the seeds and regressions, then 2000 inputs from seed 1"
        if [[ ${#extra[@]} -gt 0 ]]; then run "$t" "${extra[@]}" -- -runs=0 "${limits[@]}" "${dict[@]}"; fi
        tmp=$(mktemp -d)
        run "$t" "$tmp" "${extra[@]}" -- -seed=1 -runs=2000 "${limits[@]}" "${dict[@]}"
        rm -rf "$tmp"
    else
        echo "== $t: fuzzing for ${seconds} s"
        run "$t" "fuzz/corpus/$t" "${extra[@]}" -- -max_total_time="$seconds" "${limits[@]}" "${dict[@]}"
    fi
done
