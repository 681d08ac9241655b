#!/usr/bin/env bash
# Issue 49's noise floor: how far mask-box D-PSNR moves when only the training seed changes
# (ray batches and the field's initialisation), on one scene of one seed. The tuning bar asks
# the oracles to stay within 0.5 dB of `none`; this says what a second run gives.
# Runs each row of ROWS (default: none) on the scene out/issue49/SCENE-scene-seed-SCENE_SEED/
# with each training seed, fast preset, sparse depth, --probe, into
# out/issue49/noise/SCENE-SCENE_SEED/ROW-seed-N/ (none: seed-N/), then pools them with the
# grid's own runs (training seed = scene seed) into
# bench/results/geometry-seed-SCENE_SEED/noise-SCENE.json (rows ROW-seed-N; committed rows that
# no run here gives again are kept).
# An oracle row uses the grid's method file (out/issue49/SCENE/seed-SCENE_SEED/ROW.toml, written
# by `bench quality --oracle`, e.g. tools/diag/geometry_probe.sh SCENE SCENE_SEED), else a
# variant's (bench/results/geometry-seed-SCENE_SEED/methods/SCENE-ROW.toml, written by
# tools/diag/geometry_variants.sh, whose run out/issue49/SCENE/seed-SCENE_SEED/ROW/ is then the
# grid's row), and reads the
# `none` run of the same training seed as its geometry term's unguided field (--baseline), so
# `none` runs first. GB_NERF names the binary (default: cargo xtask).
# Usage: [ROWS="none reference-oracle score-oracle"] [SCENE_SEED=100] [GB_NERF=BIN]
#        tools/diag/dpsnr_noise.sh SCENE SEED [SEED ...]
#   e.g. tools/diag/dpsnr_noise.sh stairs 1001 1002 1003 1004   (none: about 1 min a seed;
#   reference-oracle about 1.5 min, score-oracle about 4 min)
set -euo pipefail
cd "$(dirname "$0")/../.."
# the build the README commands and CI share (.ci/run)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
scene="$1"
shift
scene_seed="${SCENE_SEED:-100}"
read -r -a rows <<< "${ROWS:-none}"
scene_dir="out/issue49/$scene-scene-seed-$scene_seed"
grid="out/issue49/$scene/seed-$scene_seed"
[ -d "$scene_dir" ] || { echo "no scene at $scene_dir: run tools/diag/geometry_probe.sh first" >&2; exit 1; }
if [ -n "${GB_NERF:-}" ]; then run=("$GB_NERF"); else run=(cargo xtask); fi
work="out/issue49/noise/$scene-$scene_seed"
# the runs of one row and training seed: none is every oracle's unguided field, so it goes first
inpaint() {
    local method="$1" seed="$2" out="$3"
    shift 3
    [ -f "$out/probe/probe.json" ] ||
        "${run[@]}" inpaint --scene "$scene_dir" --method "$method" --seed "$seed" --preset fast \
            --weights "${GB_TEST_DATA:-../shared}/weights" --export none --orbit-frames 0 \
            --probe "$@" --out "$out"
}
args=()
for row in "${rows[@]}"; do
    [ -f "$grid/$row/probe/probe.json" ] && args+=("$row-seed-$scene_seed=$grid/$row")
    method="$row"
    if [ "$row" != none ]; then
        # the grid's method file, else a variant's (tools/diag/geometry_variants.sh)
        method="$grid/$row.toml"
        [ -f "$method" ] || method="bench/results/geometry-seed-$scene_seed/methods/$scene-$row.toml"
        [ -f "$method" ] || { echo "no method file $grid/$row.toml or $method: run the grid's oracles (or the variant) first" >&2; exit 1; }
    fi
    for seed in "$@"; do
        none="$work/seed-$seed"
        inpaint none "$seed" "$none"
        out="$none"
        if [ "$row" != none ]; then
            out="$work/$row-seed-$seed"
            inpaint "$method" "$seed" "$out" --baseline "$none"
        fi
        args+=("$row-seed-$seed=$out")
    done
done
python3 tools/diag/probe_table.py --keep \
    "bench/results/geometry-seed-$scene_seed/noise-$scene.json" "${args[@]}"
