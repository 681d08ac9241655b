#!/usr/bin/env bash
# The named command's promise, checked the long way (issue 18): install `gb-nerf` with
# `cargo install --path xtask` from a throwaway clone of this repository's committed state
# into a temporary root, delete the clone, then run the README's main job (`gb-nerf
# inpaint`, the built-in defaults) from an unrelated folder with a fresh HOME and no Cargo
# environment. Prints one JSON line (timings, the run's prior folder, whether any written
# file names a source path) and exits non-zero on any failure.
#
# Usage: tools/install/check.sh [EXTRA INPAINT FLAGS...]   (e.g. --steps 20)
# The install builds the command alone (its own feature set); CARGO_TARGET_DIR, when set, is
# reused. tests/tests/installed.rs checks the same with the built binary in every test run.
set -euo pipefail
repo="$(cd "$(dirname "$0")/../.." && pwd)"
work="$(mktemp -d /tmp/gb-install.XXXXXX)"
trap 'rm -rf "$work"' EXIT

git clone -q "$repo" "$work/clone"
start=$(date +%s)
cargo install --quiet --locked --debug --path "$work/clone/xtask" --root "$work/root"
install_s=$(( $(date +%s) - start ))
clone_path="$work/clone"
rm -rf "$work/clone"

mkdir -p "$work/elsewhere" "$work/home"
cd "$work/elsewhere"
start=$(date +%s)
env -i HOME="$work/home" PATH="$work/root/bin:/usr/bin:/bin" \
    XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}" \
    gb-nerf inpaint --out run "$@" > "$work/run.log" 2>&1 || {
    tail -20 "$work/run.log" >&2
    echo "tools/install/check.sh: the installed gb-nerf failed" >&2
    exit 1
}
run_s=$(( $(date +%s) - start ))

prior="$(sed -n 's/.*"prior": "\(.*\)".*/\1/p' run/metrics.json | head -1)"
names_source=false
if grep -rqF -e "$clone_path" -e "$repo" run; then names_source=true; fi
case "$prior" in
    "$work/home/.cache/gb-nerf/"*tiny-prior) ;;
    *) echo "tools/install/check.sh: unexpected prior folder '$prior'" >&2; exit 1 ;;
esac
if $names_source; then
    echo "tools/install/check.sh: the run's files name a source path" >&2
    exit 1
fi
psnr="$(sed -n 's/^    "psnr": \([0-9.eE+-]*\),\{0,1\}$/\1/p' run/metrics.json | head -1)"
printf '{"install_seconds": %s, "default_job_seconds": %s, "binary_size": "%s", "prior": "%s", "files_name_source": %s, "mean_psnr": %s}\n' \
    "$install_s" "$run_s" "$(du -h "$work/root/bin/gb-nerf" | cut -f1)" \
    "${prior#"$work"/}" "$names_source" "${psnr:-null}"
