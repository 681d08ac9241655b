#!/usr/bin/env bash
# Issue 49's fix, measured: the oracle rows of tools/diag/geometry_probe.sh again, each with a
# [geometry] table (gb_inpaint::geometry) appended to its method file, run with --probe on
# the same scene, seed and preset. Method files land in bench/results/geometry-seed-100/methods/,
# runs in out/issue49/SCENE/seed-100/ROW-VARIANT/.
# SEED (default 100) picks the seed's runs (out/issue49/SCENE/seed-SEED/, method files in
# bench/results/geometry-seed-SEED/methods/); GB_NERF names the binary (default: cargo xtask).
# Usage: [SEED=N] [GB_NERF=BIN] tools/diag/geometry_variants.sh SCENE VARIANT "TOML LINES" [ROW ...]
#   e.g. tools/diag/geometry_variants.sh stairs depth1 "depth_weight = 1.0" reference-oracle
set -euo pipefail
cd "$(dirname "$0")/../.."
# the build the README commands and CI share (.ci/run)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
scene="$1" variant="$2" table="$3"
shift 3
rows=("$@")
[ ${#rows[@]} -gt 0 ] || rows=(reference-oracle score-oracle)
seed="${SEED:-100}"
grid="out/issue49/$scene/seed-$seed"
scene_dir="out/issue49/$scene-scene-seed-$seed"
methods="bench/results/geometry-seed-$seed/methods"
if [ -n "${GB_NERF:-}" ]; then run=("$GB_NERF"); else run=(cargo xtask); fi
mkdir -p "$methods"
# the grid's none run, when finished, is every variant's unguided field (--baseline: read, not
# trained again; the metrics are the same)
baseline=()
[ -f "$grid/none/checkpoint.bin" ] && baseline=(--baseline "$grid/none")
for row in "${rows[@]}"; do
    name="$scene-$row-$variant"
    file="$methods/$name.toml"
    # the grid's method file (the oracles'), else the built-in one (gb-nerf-unseen)
    source="$grid/$row.toml"
    [ -f "$source" ] || source="configs/methods/$row.toml"
    # the method's own [geometry] table (the built-in none and gb-nerf-unseen carry one) gives
    # way to the variant's: drop it, up to the next table
    sed -e "s/^name = \"$row\"/name = \"$row-$variant\"/" "$source" |
        awk '/^\[geometry\]$/ { skip = 1; next } /^\[/ { skip = 0 } !skip' > "$file"
    printf '\n[geometry]\n%b\n' "$table" >> "$file"
    "${run[@]}" inpaint --scene "$scene_dir" --method "$file" --seed "$seed" --preset fast \
        --weights "${GB_TEST_DATA:-../shared}/weights" --export none --orbit-frames 0 --probe \
        ${baseline[@]+"${baseline[@]}"} --out "$grid/$row-$variant"
done
