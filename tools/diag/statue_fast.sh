#!/usr/bin/env bash
# Issues 45 (item 5) and 47 (item 4) on the real capture `statue`, fast preset, sparse depth,
# flex, seed 0, one command at a time:
#   1. `--method none`, timed (its metrics.json has the training and test-view render times);
#   2. `export --run` of that run, timed: the export's cost, against the run's own renders;
#   3. `--method gb-nerf-auto` with the none run as its baseline: what it chose, and why.
# Runs land in out/statue-fast/ (a finished step is skipped), each step's wall time and output
# in bench/results/statue-fast/steps.log. GB_NERF names the binary (default: cargo xtask);
# copy it first, so that an edit of the tree does not rebuild it mid-run.
# Usage: GB_TEST_DATA=../shared [GB_NERF=/path/to/gb-nerf] tools/diag/statue_fast.sh [STEP ...]
set -euo pipefail
cd "$(dirname "$0")/../.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
: "${GB_TEST_DATA:?set GB_TEST_DATA to the shared data folder (statue and the metric weights)}"
if [ -n "${GB_NERF:-}" ]; then run=("$GB_NERF"); else run=(cargo xtask); fi
scene="$GB_TEST_DATA/data/statue"
work=out/statue-fast
log=bench/results/statue-fast/steps.log
mkdir -p "$work" "$(dirname "$log")"
steps=("$@")
[ ${#steps[@]} -eq 0 ] && steps=(none export auto)
timed() {
    local name="$1"
    shift
    echo "== $name: $* ($(date -u +%FT%TZ))" >>"$log"
    local start rc=0
    start=$(date +%s.%N)
    "$@" >>"$log" 2>&1 || rc=$?
    echo "== $name: exit $rc, wall $(echo "$(date +%s.%N) - $start" | bc) s" >>"$log"
    return "$rc"
}
for step in "${steps[@]}"; do
    case "$step" in
    none)
        [ -f "$work/none/metrics.json" ] || timed none "${run[@]}" inpaint --scene "$scene" \
            --method none --preset fast --export none --orbit-frames 0 --out "$work/none"
        ;;
    export)
        [ -f "$work/none/export/transforms.json" ] || timed export "${run[@]}" export \
            --run "$work/none" --orbit-frames 0
        ;;
    auto)
        [ -f "$work/auto/metrics.json" ] || timed auto "${run[@]}" inpaint --scene "$scene" \
            --method gb-nerf-auto --preset fast --export none --orbit-frames 0 \
            --baseline "$work/none" --out "$work/auto"
        ;;
    *) echo "unknown step $step (none, export, auto)" >&2; exit 2 ;;
    esac
done
