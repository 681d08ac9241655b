#!/usr/bin/env bash
# The README's two commands share one build: no dev-dependency may turn on a feature of a
# normal dependency that the binary's own build lacks. Resolver 2 applies a dev-dependency's
# features to test builds only, so such a feature makes `cargo xtask` after
# `cargo test --workspace` (or the other way round) compile the Burn stack a second time.
# Compares, per package, the features of what `cargo xtask` builds (xtask, normal and build
# edges) with those of what `cargo test --workspace` builds (every member, dev edges too),
# and fails naming each package whose features differ. Needs no build; run by .ci/run.
set -euo pipefail
cd "$(dirname "$0")/../.."
features() {
    # "name vX.Y.Z|f1,f2" per package, its features unioned over every line the tree prints
    # (with dev edges a package can appear in two builds with two feature sets) and sorted:
    # one "package|feature" pair a line, sorted, then joined back per package
    cargo tree --offline --locked --prefix none --format '{p}|{f}' "$@" |
        sed -e 's/ (\*)$//' -e 's/ (proc-macro)//' |
        awk -F'|' '{ n = split($2, f, ","); print $1 "|"; for (i = 1; i <= n; i++) print $1 "|" f[i] }' |
        sort -u |
        awk -F'|' '$1 != p { if (NR > 1) print p "|" substr(l, 2); p = $1; l = "" }
                   $2 != "" { l = l "," $2 }
                   END { print p "|" substr(l, 2) }'
}

binary="$(features -p xtask -e normal,build)"
tests="$(features --workspace -e normal,build,dev)"
[ "$(printf '%s\n' "$binary" | grep -c '^burn ')" -ge 1 ] || {
    echo "one_build_check: cargo tree -p xtask listed no burn package" >&2
    exit 1
}
# packages of the binary's build whose feature line is not in the test build
differ="$(comm -23 <(printf '%s\n' "$binary") <(printf '%s\n' "$tests"))"
if [ -n "$differ" ]; then
    echo "one_build_check: the test build gives these packages other features than the binary's build" >&2
    echo "(enable the feature in a normal dependency, or change the dev-dependency):" >&2
    while IFS= read -r line; do
        pkg="${line%%|*}"
        echo "  binary: $line" >&2
        printf '%s\n' "$tests" | grep -F "$pkg|" | sed 's/^/  tests:  /' >&2 || true
    done <<<"$differ"
    exit 1
fi
echo "one_build_check: $(printf '%s\n' "$binary" | wc -l) packages of the binary's build have the same features in the test build"
