#!/usr/bin/env bash
# Issue 46: `--reference auto` against `none` on the given seeds (tuning: 100 101; reporting:
# 2 3 4), fast preset, sparse depth, one scene at a time: the rows none and reference-auto
# (`bench quality --auto-reference`), plus reference-auto-unseen when UNSEEN=1 (the tuning
# seeds ran it). Reports land in bench/results/reference-auto-seed-SEED/, runs in out/q46/
# (finished runs are reused). GB_NERF names the binary to run (default: cargo xtask); copy it
# first for a long run, so that an edit of the tree does not rebuild it mid-run.
# Usage: [UNSEEN=1] [GB_NERF=/path/to/gb-nerf] tools/diag/reference_auto.sh SEED [SEED ...]
set -euo pipefail
cd "$(dirname "$0")/../.."
# the build the README commands and CI share (.ci/run)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
if [ -n "${GB_NERF:-}" ]; then run=("$GB_NERF"); else run=(cargo xtask); fi
extra=()
[ "${UNSEEN:-0}" = 1 ] && extra=(--auto-reference-unseen)
for seed in "$@"; do
    out="bench/results/reference-auto-seed-$seed"
    mkdir -p "$out"
    for scene in stairs fence alcove; do
        "${run[@]}" bench quality --scenes "$scene" --seeds "$seed" --methods none \
            --auto-reference "${extra[@]}" --work out/q46 --out "$out" --reuse-finished
    done
done
