#!/usr/bin/env bash
# Issue 49's weight of the geometry term, tuned: on one scene and seed (a tuning seed, 100 or
# 101), the grid of tools/diag/geometry_probe.sh (none and the oracles among ROWS at the
# built-in weight, through its ORACLES; finished runs are reused), then for
# each WEIGHT the ROWS again with `[geometry] depth_weight = WEIGHT` on the guided crop
# (tools/diag/geometry_variants.sh, variant `wWEIGHT`, the grid's none read as the unguided
# field), then the probe table and pictures into bench/results/geometry-seed-SEED/, the table
# as probe-SCENE-weights.json and the pictures in figures/probe-SCENE-weights/
# (tools/diag/geometry_collect.sh; the seed's probe-SCENE.json and figures/ hold older runs
# under the same row names). Pooled over the cells: tools/diag/geometry_weights_pool.py. Read
# the rows with
# `tools/diag/geometry_rows.py SCENE SEED --table probe-SCENE-weights.json --whole --before ...`.
# ROWS defaults to the reference oracle (about 2 min a run on 2 cores, fast preset); the score
# oracle and gb-nerf-unseen take about 7 min a run (the grid has no gb-nerf-unseen: give
# weight 1, the built-in one, for its reference row). GB_NERF names the binary (default: cargo
# xtask); copy it first for a long run.
# Usage: [ROWS="reference-oracle score-oracle gb-nerf-unseen"] [GB_NERF=BIN] \
#   tools/diag/geometry_weights.sh SCENE SEED WEIGHT [WEIGHT ...]
#   e.g. tools/diag/geometry_weights.sh stairs 101 0.03 0.1 0.3
set -euo pipefail
cd "$(dirname "$0")/../.."
# the build the README commands and CI share (.ci/run)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
scene="$1" seed="$2"
shift 2
[ $# -gt 0 ] || { echo "geometry_weights.sh: give at least one WEIGHT" >&2; exit 2; }
read -r -a rows <<< "${ROWS:-reference-oracle}"
# the grid: none and the oracles among ROWS at the built-in weight (the score oracle alone
# takes 7 min, so only those ROWS names)
oracles=()
for row in "${rows[@]}"; do
    case "$row" in
        reference-oracle) oracles+=(reference) ;;
        score-oracle) oracles+=(score) ;;
    esac
done
ORACLES="$(IFS=,; echo "${oracles[*]}")" tools/diag/geometry_probe.sh "$scene" "$seed"
for weight in "$@"; do
    SEED="$seed" tools/diag/geometry_variants.sh "$scene" "w$weight" \
        "depth_weight = $weight\nregion = \"crop\"" "${rows[@]}"
done
TABLE="probe-$scene-weights.json" tools/diag/geometry_collect.sh "$scene" "$seed"
