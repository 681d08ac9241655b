#!/usr/bin/env bash
# Issue 49's weight tuning over several cells, one after the other: tools/diag/geometry_weights.sh
# on each SCENE:SEED of CELLS (default: the six tuning cells, stairs, fence and alcove on seeds
# 100 and 101) with the same ROWS and WEIGHTs, a line with the date before each cell, and a
# cell that fails named and skipped. Then the pooled table of tools/diag/geometry_weights_pool.py
# for the first of ROWS. Start it in the background (a cell of the reference oracle takes about
# 6 minutes on 2 cores, one of gb-nerf-unseen about 7 minutes a weight).
# Usage: [CELLS="stairs:100 fence:101"] [ROWS=...] [GB_NERF=BIN] \
#   tools/diag/geometry_weights_cells.sh WEIGHT [WEIGHT ...]
#   e.g. ROWS=gb-nerf-unseen tools/diag/geometry_weights_cells.sh 0.1 1
set -uo pipefail
cd "$(dirname "$0")/../.."
[ $# -gt 0 ] || { echo "geometry_weights_cells.sh: give at least one WEIGHT" >&2; exit 2; }
read -r -a cells <<< "${CELLS:-stairs:100 fence:100 alcove:100 stairs:101 fence:101 alcove:101}"
read -r -a rows <<< "${ROWS:-reference-oracle}"
failed=()
for cell in "${cells[@]}"; do
    scene="${cell%%:*}" seed="${cell##*:}"
    echo "=== $scene $seed $(date -u +%FT%TZ)"
    tools/diag/geometry_weights.sh "$scene" "$seed" "$@" || failed+=("$cell")
done
echo "=== done $(date -u +%FT%TZ)"
# the built-in weight 1 always (the pool reads a weight given twice once)
python3 tools/diag/geometry_weights_pool.py --row "${rows[0]}" --weights "$@" 1 \
    --cells "${cells[@]}"
if [ ${#failed[@]} -gt 0 ]; then
    echo "geometry_weights_cells.sh: these cells failed: ${failed[*]}" >&2
    exit 1
fi
