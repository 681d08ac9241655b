#!/usr/bin/env bash
# Issue 49: does the geometry term cost the view away from the hole through the hash table's
# collisions? The same cell as the `fast` runs of tools/diag/geometry_seeds.sh (default
# gb-nerf-unseen with and without the term, and none), with the fast preset's hash table made
# 2^LOG2 entries a level (fast: 2^14); then tools/diag/where_psnr.py on these runs beside the
# fast ones still in out/issue49/SCENE/seed-SEED/ (none, gb-nerf-unseen and, from
# geometry_variants.sh, gb-nerf-unseen-noterm). If a larger table shrinks the term's cost over
# the rest of the view, the cost is capacity; if not, it goes through the density MLP.
# Runs in out/issue49/capacity/SCENE-SEED-tLOG2/ (with STEPS: ...-stepsN/, and the table there);
# the preset and method files beside them;
# the table in bench/results/geometry-seed-SEED/where-psnr-SCENE-t14-tLOG2.json.
# GB_NERF names the binary (default: cargo xtask); STEPS overrides the preset's steps (a smoke).
# A run whose metrics.json exists is reused as it is (whichever binary made it).
# Usage: [GB_NERF=BIN] [STEPS=N] tools/diag/geometry_capacity.sh SCENE SEED LOG2
#   e.g. tools/diag/geometry_capacity.sh stairs 3 16   (about 10 min)
set -euo pipefail
cd "$(dirname "$0")/../.."
# the build the README commands and CI share (.ci/run)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
scene="$1" seed="$2" log2="$3"
[ "$log2" != 14 ] || { echo "LOG2 14 is the fast preset itself: its runs are the grid's" >&2; exit 1; }
scene_dir="out/issue49/$scene-scene-seed-$seed"
[ -d "$scene_dir" ] || { echo "no scene at $scene_dir: run tools/diag/geometry_seeds.sh first" >&2; exit 1; }
if [ -n "${GB_NERF:-}" ]; then run=("$GB_NERF"); else run=(cargo xtask); fi
work="out/issue49/capacity/$scene-$seed-t$log2${STEPS:+-steps$STEPS}"
mkdir -p "$work"
preset="$work/fast-t$log2.toml"
sed -e "s/^name = \"fast\"/name = \"fast-t$log2\"/" \
    -e "s/^log2_table_size = .*/log2_table_size = $log2/" configs/presets/fast.toml > "$preset"
grep -q "^log2_table_size = $log2$" "$preset" || { echo "$preset: no log2_table_size line" >&2; exit 1; }
# the default method without the term: its [geometry] table replaced by a zero weight
noterm="$work/gb-nerf-unseen-noterm.toml"
sed -e 's/^name = "gb-nerf-unseen"/name = "gb-nerf-unseen-noterm"/' configs/methods/gb-nerf-unseen.toml |
    awk '/^\[geometry\]$/ { skip = 1; next } /^\[/ { skip = 0 } !skip' > "$noterm"
printf '\n[geometry]\ndepth_weight = 0.0\n' >> "$noterm"
steps=()
[ -n "${STEPS:-}" ] && steps=(--steps "$STEPS")
inpaint() {
    local method="$1" out="$2"
    shift 2
    [ -f "$out/metrics.json" ] ||
        "${run[@]}" inpaint --scene "$scene_dir" --method "$method" --seed "$seed" \
            --preset "$preset" ${steps[@]+"${steps[@]}"} --weights "${GB_TEST_DATA:-../shared}/weights" \
            --export none --orbit-frames 0 --probe "$@" --out "$out"
}
inpaint none "$work/none"
inpaint gb-nerf-unseen "$work/gb-nerf-unseen" --baseline "$work/none"
inpaint "$noterm" "$work/gb-nerf-unseen-noterm"
grid="out/issue49/$scene/seed-$seed"
rows=()
for row in none gb-nerf-unseen gb-nerf-unseen-noterm; do
    [ -d "$grid/$row/renders" ] && rows+=("$row-t14=$grid/$row")
    rows+=("$row-t$log2=$work/$row")
done
out="bench/results/geometry-seed-$seed/where-psnr-$scene-t14-t$log2.json"
[ -n "${STEPS:-}" ] && out="$work/where-psnr.json"
mkdir -p "$(dirname "$out")"
python3 tools/diag/where_psnr.py "$scene_dir" "${rows[@]}" --out "$out"
