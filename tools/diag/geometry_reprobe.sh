#!/usr/bin/env bash
# Issue 49's runs of one scene probed again from their checkpoints (tools/diag/reprobe.sh; no
# training, the same metrics), for the probe fields added after they were made (the RMS
# errors and the D-PSNR's scales), pooled into bench/results/geometry-seed-100/probe-SCENE.json.
# Usage: tools/diag/geometry_reprobe.sh SCENE [ROW ...]   (default: every run of the scene
# with a checkpoint; a run probed with these fields already is pooled as it is)
set -euo pipefail
cd "$(dirname "$0")/../.."
scene="$1"
shift
grid="out/issue49/$scene/seed-100"
again="out/issue49-reprobe/$scene"
rows=("$@")
if [ ${#rows[@]} -eq 0 ]; then
    for run in "$grid"/*/; do
        [ -f "$run/checkpoint.bin" ] && rows+=("$(basename "$run")")
    done
fi
has_scales() { [ -f "$1/probe/probe.json" ] && grep -q rendered_max_in_box "$1/probe/probe.json"; }
args=()
for row in "${rows[@]}"; do
    if has_scales "$grid/$row"; then
        args+=("$row=$grid/$row")
        continue
    fi
    has_scales "$again/$row" || tools/diag/reprobe.sh "$grid/$row" "$again/$row"
    args+=("$row=$again/$row")
done
python3 tools/diag/probe_table.py "bench/results/geometry-seed-100/probe-$scene.json" "${args[@]}"
