#!/usr/bin/env bash
# The renderer's cost (issue 28's bar: a shaded picture takes at most twice the unshaded
# time): `render --algo ll` of one mesh, `--shade id` (the algorithm's own composite, the
# unshaded picture) and `--shade lit` (every kept fragment shaded from its interpolated
# normal and material), alternated in ROUNDS pairs in one run so that both sides see the
# same minutes of a noisy shared machine. Each side's time is the frame (`wall_ms`: clears,
# passes, resolve) plus the picture (`picture_ms`: shading and compositing, or the copy of
# the algorithm's image; writing the PNG is not counted). Prints each pair, the medians and
# the ratio of the medians, and the CPU model.
# Each side's JSON is captured first and parsed after it has exited (see ci/pairs.sh).
# Usage: bash ci/render_bench.sh [ROUNDS] [MESH] [SIZE] [THREADS]
#   defaults: 5 rounds, ../shared/models/dragon.obj.gz (871K triangles), 1024, 2 threads.
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-5}
mesh=${2:-../shared/models/dragon.obj.gz}
size=${3:-1024}
threads=${4:-2}
[ -f "$mesh" ] || { echo "$mesh: not found (give a mesh: bash ci/render_bench.sh 5 assets/bunny.obj.gz)" >&2; exit 2; }
cargo build --release --quiet
bin=target/release/fragrace
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//'), $(nproc) cores"
echo "render --algo ll --obj $mesh at ${size}x${size}, $threads threads, $rounds alternating pairs"
results=""
for r in $(seq 1 "$rounds"); do
    for shade in id lit; do
        json=$("$bin" render --obj "$mesh" --algo ll --width "$size" --height "$size" \
            --threads "$threads" --shade "$shade" --out "$out/$shade.png" --json 2>/dev/null)
        line=$(python3 -c '
import json, sys
v = json.loads(sys.argv[1].splitlines()[-1])
print(v["shade"], v["wall_ms"], v["picture_ms"], v["fragments"])' "$json")
        results+="$r $line"$'\n'
    done
done
python3 - "$results" <<'PY'
import statistics, sys
rows = [l.split() for l in sys.argv[1].strip().splitlines()]
tot = {"id": [], "lit": []}
for r, shade, frame, pic, frags in rows:
    t = float(frame) + float(pic)
    tot[shade].append(t)
    print(f"  pair {r} {shade:>3}: frame {float(frame):8.1f} ms + picture {float(pic):7.1f} ms = {t:8.1f} ms ({frags} fragments)")
u, s = statistics.median(tot["id"]), statistics.median(tot["lit"])
print(f"median unshaded (id) {u:.1f} ms, shaded (lit) {s:.1f} ms, ratio {s / u:.2f} (bar: at most 2)")
PY
