#!/usr/bin/env bash
# Side by side, alternating pairs in one run: the frame of an algorithm with and without
# occupancy culling under the parallel executor (bench's median of --frames frames each),
# and the median ratio culled / plain. Each side's JSON is captured whole before parsing.
#   bash ci/occupancy_pairs.sh [ALGO] [SCENE] [SIZE] [PAIRS]
set -euo pipefail
cd "$(dirname "$0")/.."
algo=${1:-kplus}; scene=${2:-hairball}; size=${3:-512}; pairs=${4:-5}
cargo build --release -q
bin=target/release/fragrace
common=(bench --scene "$scene" --algo "$algo" --width "$size" --height "$size" --exec parallel --threads 2 --frames 5 --warmup 1 --json)
echo "CPU: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) cores"
echo "$algo on $scene ${size}x${size}, k = 8, d = 32 (exact range), parallel, 2 threads"
ratios=()
for i in $(seq "$pairs"); do
    plain=$("$bin" "${common[@]}")
    culled=$("$bin" "${common[@]}" --occupancy 32)
    p=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["median_ms"])' "$plain")
    c=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["median_ms"])' "$culled")
    r=$(python3 -c "print(f'{$c / $p:.3f}')")
    ratios+=("$r")
    printf 'pair %d: plain %.1f ms, culled %.1f ms, ratio %s\n' "$i" "$p" "$c" "$r"
done
python3 -c "import statistics,sys; print('median ratio culled / plain:', statistics.median(map(float, sys.argv[1:])))" "${ratios[@]}"
