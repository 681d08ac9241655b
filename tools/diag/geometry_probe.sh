#!/usr/bin/env bash
# Issue 49's diagnosis: none, reference-oracle and score-oracle on tuning seed 100 of one
# scene (fast preset, sparse depth), each run with --probe; the quality report lands in
# bench/results/geometry-seed-100/, the runs in out/issue49/.
# Usage: tools/diag/geometry_probe.sh SCENE
set -euo pipefail
cd "$(dirname "$0")/../.."
scene="$1"
cargo xtask bench quality --scenes "$scene" --seeds 100 --methods none \
    --oracle reference,score --probe --work out/issue49 --out bench/results/geometry-seed-100
