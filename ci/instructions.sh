#!/usr/bin/env bash
# Instructions per fragment inside the fused pass (`fused::run_fused`, inclusive), counted
# by callgrind: repeatable for one binary and input whatever else the machine is doing, so
# it measures per-fragment cost where wall-clock timings are too noisy.
# Usage: bash ci/instructions.sh [extra `fragrace bench` flags, e.g. --no-lockstep]
# Env: CASES (default "bunny.obj.gz:2048"; MESH:SIZE, space-separated), models in ../shared/models.
set -euo pipefail
cd "$(dirname "$0")/.."
command -v valgrind >/dev/null || { echo "needs valgrind (callgrind_annotate comes with it)" >&2; exit 1; }
cargo build --release -q
F=./target/release/fragrace
M=../shared/models
out=$(mktemp)
trap 'rm -f "$out"' EXIT
for c in ${CASES:-bunny.obj.gz:2048}; do
    mesh=${c%%:*}
    size=${c##*:}
    args=(bench --obj "$M/$mesh" --algo count --threads 1 --width "$size" --height "$size" --frames 1 --warmup 0 --json "$@")
    valgrind --tool=callgrind --callgrind-out-file="$out" "$F" "${args[@]}" >/dev/null 2>&1
    ir=$(callgrind_annotate --inclusive=yes "$out" | grep 'fused::run_fused \[' | awk '{print $1}' | tr -d ,)
    frags=$("$F" "${args[@]}" | python3 -c "import json,sys; print(json.load(sys.stdin)['fragments'])")
    echo "$mesh $size $*: $ir instructions in the fused pass, $frags fragments, $(python3 -c "print(round($ir / $frags, 1))") per fragment"
done
