#!/usr/bin/env bash
# Issue 49's noise floor: how far `none`'s mask-box D-PSNR moves when only the training seed
# changes (ray batches and the field's initialisation), on one scene of one seed. The tuning
# bar asks the oracles to stay within 0.5 dB of `none`; this says what a second run of `none`
# itself gives. Runs `--method none` on the scene of out/issue49/SCENE-scene-seed-SCENE_SEED/
# (made by the grid) with each training seed, fast preset, sparse depth, --probe, into
# out/issue49/noise/SCENE-SCENE_SEED/seed-N/, then pools them with the grid's own none run
# (training seed = scene seed) into bench/results/geometry-seed-SCENE_SEED/noise-SCENE.json.
# GB_NERF names the binary (default: cargo xtask).
# Usage: [SCENE_SEED=100] [GB_NERF=BIN] tools/diag/dpsnr_noise.sh SCENE SEED [SEED ...]
#   e.g. tools/diag/dpsnr_noise.sh stairs 1001 1002 1003 1004   (about 1 min a seed)
set -euo pipefail
cd "$(dirname "$0")/../.."
# the build the README commands and CI share (.ci/run)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
scene="$1"
shift
scene_seed="${SCENE_SEED:-100}"
scene_dir="out/issue49/$scene-scene-seed-$scene_seed"
grid_none="out/issue49/$scene/seed-$scene_seed/none"
[ -d "$scene_dir" ] || { echo "no scene at $scene_dir: run tools/diag/geometry_seeds.sh first" >&2; exit 1; }
if [ -n "${GB_NERF:-}" ]; then run=("$GB_NERF"); else run=(cargo xtask); fi
work="out/issue49/noise/$scene-$scene_seed"
args=()
[ -f "$grid_none/probe/probe.json" ] && args+=("none-seed-$scene_seed=$grid_none")
for seed in "$@"; do
    out="$work/seed-$seed"
    [ -f "$out/probe/probe.json" ] ||
        "${run[@]}" inpaint --scene "$scene_dir" --method none --seed "$seed" --preset fast \
            --weights "${GB_TEST_DATA:-../shared}/weights" --export none --orbit-frames 0 \
            --probe --out "$out"
    args+=("none-seed-$seed=$out")
done
python3 tools/diag/probe_table.py "bench/results/geometry-seed-$scene_seed/noise-$scene.json" \
    "${args[@]}"
