#!/usr/bin/env bash
# Issue 45, item 3: `gb-nerf-auto` (two pseudo-holes that look like the hole, trials from a
# shared unguided prefix) against `none` on one seed (tuning: 100 101), fast preset, sparse
# depth, one scene at a time. With GUIDED=1 the row `gb-nerf-unseen` runs too: the one guided
# run that the trials' cost is measured against, in the same benchmark run. Reports land in
# bench/results/auto-holes-seed-SEED/, runs in out/q45/ (finished runs are reused). GB_NERF
# names the binary to run (default: cargo xtask), so that a long run is not rebuilt from a
# tree being edited.
# OUT names another folder for the reports (a re-run beside the first).
# Usage: [GUIDED=1] [OUT=DIR] [GB_NERF=/path/to/gb-nerf] tools/diag/auto_tuning.sh SEED [SCENE ...]
set -euo pipefail
cd "$(dirname "$0")/../.."
# the build the README commands and CI share (.ci/run)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
# the trials rank by ST-LPIPS too, and the reports need it: its weights are in the shared data
: "${GB_TEST_DATA:?set GB_TEST_DATA to the shared data folder (its weights/ hold ST-LPIPS)}"
seed="$1"
shift
scenes=("$@")
[ ${#scenes[@]} -eq 0 ] && scenes=(stairs fence alcove)
if [ -n "${GB_NERF:-}" ]; then run=("$GB_NERF"); else run=(cargo xtask); fi
methods=none,gb-nerf-auto
[ "${GUIDED:-0}" = 1 ] && methods=none,gb-nerf-auto,gb-nerf-unseen
out="${OUT:-bench/results/auto-holes-seed-$seed}"
mkdir -p "$out"
for scene in "${scenes[@]}"; do
    "${run[@]}" bench quality --scenes "$scene" --seeds "$seed" --methods "$methods" \
        --work out/q45 --out "$out" --reuse-finished
done
