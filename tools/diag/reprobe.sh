#!/usr/bin/env bash
# Probes a finished run again without training it again: copies its checkpoint and config to
# DEST and resumes there with --probe (the checkpoint is at the last step, so the run only
# renders, scores and probes). For probe fields added after the run was made.
# Usage: tools/diag/reprobe.sh RUN_DIR DEST
set -euo pipefail
cd "$(dirname "$0")/../.."
# the build the README commands and CI share (.ci/run)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/gb-nerf-rs/target}"
run="${1%/}" dest="${2%/}"
[ -f "$run/checkpoint.bin" ] || { echo "reprobe.sh: $run/checkpoint.bin: no checkpoint" >&2; exit 1; }
mkdir -p "$dest"
cp "$run/checkpoint.bin" "$run/config.toml" "$run/train_log.jsonl" "$dest/"
reproduce="$(sed -n 's/^reproduce = "\(.*\)"$/\1/p' "$dest/config.toml")"
[ -n "$reproduce" ] || { echo "reprobe.sh: $dest/config.toml: no reproduce line" >&2; exit 1; }
# the run's own folder becomes DEST (its config.toml is the preset and the method)
args="${reproduce//$run/$dest}"
# written as `cargo xtask inpaint ...` or, by bench quality's runs, `gb-nerf inpaint ...`
args="${args#cargo xtask }"
args="cargo xtask ${args#gb-nerf }"
read -ra argv <<<"$args"
"${argv[@]}" --resume --probe --export none --orbit-frames 0 \
    --weights "${GB_TEST_DATA:-../shared}/weights"
