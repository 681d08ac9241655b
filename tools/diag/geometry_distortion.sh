#!/usr/bin/env bash
# Issue 49: does the distortion loss on the geometry term's rays give back the appearance the
# term costs on `stairs`? With the term the hidden surface is held on average and smeared in
# depth (tools/diag/weight_spread.py: spread 0.18-0.19 of the depth against `none`'s 0.14-0.15);
# `[geometry] distortion_weight` (mip-NeRF 360's loss on the same rays, in the term, off by
# default) penalises exactly that spread.
# ROW (default score-oracle, the cell that misses) with the built-in term (depth_weight 1,
# crop) plus distortion_weight WEIGHT: on the grid's scene of tuning seed 100 with training
# seed 100 (tools/diag/geometry_variants.sh: variant distWEIGHT, run
# out/issue49/SCENE/seed-100/ROW-distWEIGHT/), then with each other TRAINING_SEED paired with
# `none` (tools/diag/dpsnr_noise.sh: rows ROW-distWEIGHT-seed-N of
# bench/results/geometry-seed-100/noise-SCENE.json), then tools/diag/paired_noise.py with the
# held row without and with the loss (each against `none`), and tools/diag/weight_spread.py on both.
# Needs the grid's ROW method file and runs (tools/diag/geometry_probe.sh SCENE 100); the none
# runs of the training seeds are made when missing (dpsnr_noise.sh). GB_NERF names the binary.
# Usage: [GB_NERF=BIN] [ROW=score-oracle] tools/diag/geometry_distortion.sh SCENE WEIGHT [TRAINING_SEED ...]
#   e.g. tools/diag/geometry_distortion.sh stairs 0.01 1001 1002 1003 1004   (about 4.5 min a run)
set -euo pipefail
cd "$(dirname "$0")/../.."
scene="$1" weight="$2"
shift 2
row="${ROW:-score-oracle}"
[[ "$weight" =~ ^[0-9]+(\.[0-9]+)?$ ]] || { echo "WEIGHT must be a number >= 0, got '$weight'" >&2; exit 1; }
variant="dist$weight"
grid="out/issue49/$scene/seed-100"
[ -f "$grid/$row.toml" ] || { echo "no method file $grid/$row.toml: run tools/diag/geometry_probe.sh $scene 100 first" >&2; exit 1; }
[ -f "$grid/$row-$variant/probe/probe.json" ] ||
    SEED=100 tools/diag/geometry_variants.sh "$scene" "$variant" \
        "depth_weight = 1.0\nregion = \"crop\"\ndistortion_weight = $weight" "$row"
# the seed-100 run joins the table as the row's grid run, beside the other training seeds
ROWS="$row-$variant" SCENE_SEED=100 tools/diag/dpsnr_noise.sh "$scene" "$@"
table="bench/results/geometry-seed-100/noise-$scene.json"
python3 tools/diag/paired_noise.py "$table" "$row" "$row-$variant"
python3 tools/diag/weight_spread.py "$table" --rows "none,$row-seed,$row-$variant"
