#!/usr/bin/env bash
# Issue 49's diagnosis and its measurement: none, reference-oracle and score-oracle on one
# scene and seed (fast preset, sparse depth; the seed defaults to tuning seed 100), each run
# with --probe; the quality report lands in bench/results/geometry-seed-SEED/, the runs in
# out/issue49/ (finished runs are reused). GB_NERF names the binary to run (default: cargo
# xtask), so that a long run is not rebuilt from a tree being edited.
# ORACLES picks the oracle rows (default "reference,score"; empty: none alone).
# Usage: [ORACLES=LIST] [GB_NERF=/path/to/gb-nerf] tools/diag/geometry_probe.sh SCENE [SEED]
set -euo pipefail
cd "$(dirname "$0")/../.."
# the build the README commands and CI share (.ci/run)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
scene="$1" seed="${2:-100}"
if [ -n "${GB_NERF:-}" ]; then run=("$GB_NERF"); else run=(cargo xtask); fi
oracle=()
oracles="${ORACLES-reference,score}"
[ -n "$oracles" ] && oracle=(--oracle "$oracles")
"${run[@]}" bench quality --scenes "$scene" --seeds "$seed" --methods none \
    ${oracle[@]+"${oracle[@]}"} --probe --work out/issue49 \
    --out "bench/results/geometry-seed-$seed" --reuse-finished
