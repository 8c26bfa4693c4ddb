#!/usr/bin/env bash
# Side-by-side performance: fragrace's parallel executor vs Mesa llvmpipe running the same
# `count` shader (../shared/peers/llvmpipe/oit.py), same mesh, view, resolution and thread
# count; then the scheduled executor's steps per second and explore executions per second.
# Prints a markdown table (docs/performance.md holds the last run). Needs ../shared and,
# for the llvmpipe column, the peer's dependencies (libegl1 libegl-mesa0 libgl1-mesa-dri;
# pip install moderngl numpy pillow).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q
F=./target/release/fragrace
M=../shared/models
PEER=../shared/peers/llvmpipe/oit.py
have_peer=0
python3 -c "import moderngl" 2>/dev/null && have_peer=1
# The floor columns (`bench --floor`): the frame's own atomic adds replayed with nothing
# around them on the same threads, alone and with the fresh buffer and read-back: no
# implementation of the `count` frame on this machine can be faster than the first.
echo "| mesh | size | threads | fragrace frame ms (median, lockstep warps) | passes alone | --no-lockstep frame | floor: adds alone / with buffer | llvmpipe ms (median) | ratio (lockstep) | ratio (--no-lockstep) | floor / llvmpipe |"
echo "|---|---|---|---|---|---|---|---|---|---|---|"
for case in "dragon.obj.gz 512" "dragon.obj.gz 2048" "bunny.obj.gz 2048" "dragon_res2.obj.gz 512"; do
    set -- $case
    for threads in 1 2; do
        read -r ours passes < <(python3 -c "import json,sys; d=json.load(sys.stdin); print(round(d['median_ms'], 2), round(d['passes_median_ms'], 2))" <<< "$($F bench --obj "$M/$1" --algo count --threads "$threads" --width "$2" --height "$2" --frames 15 --warmup 3 --json)")
        read -r free floor floor_frame < <(python3 -c "import json,sys; d=json.load(sys.stdin); print(round(d['median_ms'], 2), round(d['floor_atomics_ms'], 2), round(d['floor_frame_ms'], 2))" <<< "$($F bench --obj "$M/$1" --algo count --threads "$threads" --width "$2" --height "$2" --frames 15 --warmup 3 --no-lockstep --floor --json)")
        theirs="-"
        ratio="-"
        ratio_free="-"
        ratio_floor="-"
        if [ "$have_peer" = 1 ] && [ "$threads" = 2 ]; then
            theirs=$(python3 -c "import json,sys; d=json.load(sys.stdin); print(round(d.get('median_ms', d.get('frame_ms_median', 0)), 2))" <<< "$(LP_NUM_THREADS=$threads python3 "$PEER" "$M/$1" --algo count --width "$2" --height "$2" --frames 15 --warmup 3 2>/dev/null | tail -1)")
            ratio=$(python3 -c "print(f'{$ours / $theirs:.2f}' if $theirs else '-')")
            ratio_free=$(python3 -c "print(f'{$free / $theirs:.2f}' if $theirs else '-')")
            ratio_floor=$(python3 -c "print(f'{$floor / $theirs:.2f} / {$floor_frame / $theirs:.2f}' if $theirs else '-')")
        fi
        echo "| $1 | $2 | $threads | $ours | $passes | $free | $floor / $floor_frame | $theirs | $ratio | $ratio_free | $ratio_floor |"
    done
done
echo
# Unbinned counting passes against the tile-binned path (`--binning always`), same frames.
for size in 512 2048; do
    for binning in auto always; do
        echo "dragon $size, 2 threads, --no-lockstep --binning $binning: $(python3 -c "import json,sys; d=json.load(sys.stdin); print(round(d['median_ms'], 2), 'ms')" <<< "$($F bench --obj "$M/dragon.obj.gz" --algo count --threads 2 --width $size --height $size --frames 15 --warmup 3 --no-lockstep --binning $binning --json)")"
    done
done
echo
$F bench --scene hairball --algo count-plain --exec scheduled --width 128 --height 128 --frames 5 --warmup 1
cargo bench --bench explore -- --warm-up-time 1 --measurement-time 5 2>&1 | grep -E "^ll-push|thrpt" | head -4
