#!/usr/bin/env bash
# Times the README's two commands from an empty target folder, in one order:
# `cargo xtask --help` (builds the gb-nerf binary, then prints its help) and
# `cargo test --workspace --no-run` (the test build), and writes one JSON.
# Usage: tools/dev/build_order.sh OUT.json [TARGET_DIR] [xtask-first|tests-first]
# The crates must already be fetched (nothing is downloaded). Run it alone on the machine.
# It builds a clean checkout of HEAD (a git worktree), so edits in progress do not leak in;
# a failing command stops it.
set -euo pipefail
shopt -s inherit_errexit
cd "$(dirname "$0")/../.."
out="$(realpath -m "$1")"
target="${2:-$(mktemp -d /tmp/gb-build-order.XXXXXX)}"
order="${3:-xtask-first}"
case "$order" in xtask-first | tests-first) ;; *)
    echo "build_order.sh: order '$order': expected xtask-first or tests-first" >&2
    exit 2
    ;;
esac
tree="$(mktemp -d /tmp/gb-build-order-tree.XXXXXX)"
git worktree add --detach "$tree" HEAD >/dev/null
trap 'git worktree remove --force "$tree"' EXIT
cd "$tree"
rm -rf "$target" && mkdir -p "$target"
export CARGO_TARGET_DIR="$target"
timed() { # label, command...
    local label="$1"; shift
    local t0 t1 log
    log="$(mktemp)"
    t0=$(date +%s.%N)
    if ! "$@" >"$log" 2>&1; then
        tail -20 "$log" >&2
        echo "build_order.sh: $label failed" >&2
        exit 1
    fi
    t1=$(date +%s.%N)
    printf '{"command": "%s", "wall_s": %.1f}' "$label" "$(echo "$t1 - $t0" | bc)"
    rm -f "$log"
}
if [ "$order" = xtask-first ]; then
    first=$(timed "cargo xtask --help" cargo xtask --help)
    second=$(timed "cargo test --workspace --no-run" cargo test --workspace --no-run)
else
    first=$(timed "cargo test --workspace --no-run" cargo test --workspace --no-run)
    second=$(timed "cargo xtask --help" cargo xtask --help)
fi
cat >"$out" <<JSON
{
  "what": "the README's two commands from an empty target folder, $order, each alone on the machine",
  "date": "$(date -u +%Y-%m-%dT%H:%M:%SZ)",
  "machine": "$(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)",
  "commit": "$(git rev-parse --short HEAD)",
  "rustc": "$(rustc --version)",
  "steps": [$first, $second]
}
JSON
rm -rf "$target"
cat "$out"
