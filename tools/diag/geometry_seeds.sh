#!/usr/bin/env bash
# Issue 49's report on the reporting seeds: none, the default gb-nerf-unseen (with the geometry
# term, on by default) and both oracles on one scene, fast preset, sparse depth, one seed per
# bench quality call so that each lands on its own (finished runs are reused: a last call with
# every seed only pools them). Runs in out/issue49/, reports in bench/results/geometry-seeds-2-4/.
# GB_NERF names the binary (default: cargo xtask); copy it first for a long run, so that an
# edited tree is not rebuilt under it.
# The runs in out/ do not outlive a machine, so the reports of cells run on different days are
# pooled from bench/results/ by tools/diag/geometry_table.py (the before/after table against the
# older runs without the term).
# Usage: [GB_NERF=BIN] tools/diag/geometry_seeds.sh SCENE SEED [SEED ...]
#   e.g. tools/diag/geometry_seeds.sh stairs 2 3 4   (about 20 min a seed)
set -euo pipefail
cd "$(dirname "$0")/../.."
# the build the README commands and CI share (.ci/run)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
scene="$1"
shift
if [ -n "${GB_NERF:-}" ]; then run=("$GB_NERF"); else run=(cargo xtask); fi
out="bench/results/geometry-seeds-2-4"
mkdir -p "$out"
quality() {
    "${run[@]}" bench quality --scenes "$scene" --seeds "$1" --methods none,gb-nerf-unseen \
        --oracle reference,score --probe --work out/issue49 --out "$out" --reuse-finished
}
for seed in "$@"; do
    quality "$seed"
done
# the pooled report of every seed given (all finished by now)
[ $# -gt 1 ] && quality "$(IFS=,; echo "$*")"
exit 0
