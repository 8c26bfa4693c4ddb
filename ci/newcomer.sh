#!/usr/bin/env bash
# A newcomer's first hour, automated: clones this repository (its committed HEAD) into a
# temporary directory and runs every command of README.md's code blocks as written, in
# order, from the clone's top directory. Fails (exit 1) if any command fails, and names it.
#
# Usage: bash ci/newcomer.sh [--keep]
#   --keep   leave the clone (and its target/) in place for a look afterwards.
# NEWCOMER_TARGET=DIR reuses a cargo target directory (faster; no longer a first build).
# NEWCOMER_SKIP=REGEX skips the commands it matches (e.g. 'cargo test' to try the rest),
# and says so.
#
# Takes a release build, the README's commands and `cargo test --workspace` from nothing:
# about 15 minutes on 2 cores. Not part of .ci/run (it would double CI's time).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
keep=0
[ "${1:-}" = "--keep" ] && keep=1

tmp="$(mktemp -d "${TMPDIR:-/tmp}/fragrace-newcomer.XXXXXX")"
if [ "$keep" = 0 ]; then
    trap 'rm -rf "$tmp"' EXIT
fi
git clone --quiet "$here" "$tmp/fragrace"
cd "$tmp/fragrace"
if [ -n "${NEWCOMER_TARGET:-}" ]; then
    export CARGO_TARGET_DIR="$NEWCOMER_TARGET"
fi
echo "fresh clone of $(git rev-parse --short HEAD) in $tmp/fragrace"

# Every line of a ```sh block that starts with `cargo ` (a trailing `# comment` removed).
mapfile -t commands < <(awk '
    /^```/ { inblock = !inblock && ($0 ~ /^```(sh|bash|console)?[[:space:]]*$/); next }
    inblock && /^cargo / { sub(/[[:space:]]+#.*$/, ""); print }
' README.md)
if [ "${#commands[@]}" = 0 ]; then
    echo "no commands found in README.md" >&2
    exit 1
fi

failed=()
skipped=0
for c in "${commands[@]}"; do
    if [ -n "${NEWCOMER_SKIP:-}" ] && [[ "$c" =~ $NEWCOMER_SKIP ]]; then
        echo "== skipped (NEWCOMER_SKIP): $c"
        skipped=$((skipped + 1))
        continue
    fi
    t0=$SECONDS
    echo "== $c"
    if bash -c "$c" >"$tmp/out.txt" 2>&1; then
        echo "== ok ($((SECONDS - t0)) s)"
    else
        tail -n 20 "$tmp/out.txt"
        echo "== FAILED ($((SECONDS - t0)) s): $c"
        failed+=("$c")
    fi
done

echo
echo "${#commands[@]} README commands, ${#failed[@]} failed, $skipped skipped"
for c in "${failed[@]}"; do
    echo "  failed: $c"
done
[ "${#failed[@]}" = 0 ]
