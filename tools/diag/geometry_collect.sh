#!/usr/bin/env bash
# Collects issue 49's runs of one scene (tools/diag/geometry_probe.sh, geometry_variants.sh):
# the probe pictures of the first test view of each run into
# bench/results/geometry-seed-SEED/figures/, and the pooled probe table into
# bench/results/geometry-seed-SEED/probe-SCENE.json (tools/diag/probe_table.py). SEED defaults
# to tuning seed 100.
# The table keeps its committed rows that no run in out/ gives again (probe_table.py --keep).
# TABLE names another table in the same folder (geometry_weights.sh: probe-SCENE-weights.json),
# so that rows of the same name but another meaning (an older binary's) are not replaced; its
# pictures then go to figures/NAME/ (without .json), beside the older runs' pictures.
# Usage: [TABLE=NAME.json] tools/diag/geometry_collect.sh SCENE [SEED]
set -euo pipefail
cd "$(dirname "$0")/../.."
scene="$1" seed="${2:-100}"
grid="out/issue49/$scene/seed-$seed"
dest="bench/results/geometry-seed-$seed"
table="${TABLE:-}"
figures="$dest/figures${table:+/${table%.json}}"
mkdir -p "$figures"
args=()
for run in "$grid"/*/; do
    run="${run%/}"
    row="$(basename "$run")"
    [ -f "$run/probe/probe.json" ] || continue
    args+=("$row=$run")
    first="$(ls "$run/probe/" | grep '_probe.png$' | head -1)"
    view="${first%_probe.png}"
    cp "$run/probe/${view}_probe.png" "$figures/$scene-$row-${view}_probe.png"
    cp "$run/probe/${view}_rays.svg" "$figures/$scene-$row-${view}_rays.svg"
done
python3 tools/diag/probe_table.py --keep "$dest/${table:-probe-$scene.json}" "${args[@]}"
