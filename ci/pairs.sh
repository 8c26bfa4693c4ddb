#!/usr/bin/env bash
# Side-by-side pairs against llvmpipe, alternated: on these noisy VMs one run of each side
# (as in ci/bench.sh) can land in different minutes, so this runs ROUNDS pairs per case, the
# llvmpipe peer just before fragrace each time (same mesh, view, size and thread count), and
# prints each pair's ratio and, per case, the median of the ratios.
# fragrace runs its `parallel` executor with `--no-lockstep`; the bar of issue 2 is 0.2.
# A frame is timed as the peer times one (clears and passes); fragrace's self-check (the sum
# of the counts read back, which the peer does untimed) is timed apart and shown too.
# Needs ../shared and the peer's dependencies (see ci/bench.sh).
# Each side's JSON is captured first and parsed after it has exited (`python3 <<< "$(...)"`):
# piping it into python3 started the interpreter while a 75 ms fragrace run was timing its
# frames, and on two cores that took one from it (bunny @2048: 6.1-8.1 ms piped against
# 4.4-5.8 ms captured, alternating runs). ci/bench.sh and ci/ab.sh do the same.
# Usage: bash ci/pairs.sh [ROUNDS] [THREADS] [ALGO]   (defaults: 3 rounds, 2 threads, count)
# ALGO is fragrace's name; the peer runs its counterpart (count, ll, kb-rmw -> kbuf-rmw,
# kb-atomic32 -> kbuf-atomic; both with k = 8, the peer's default).
# Env: CASES (default "dragon.obj.gz:512 dragon.obj.gz:2048 bunny.obj.gz:2048"; MESH:SIZE);
# LOCKSTEP=1 runs fragrace with its default lockstep warps instead of --no-lockstep;
# FRAGRACE=PATH runs that binary instead of building this tree's release one (a build to
# compare with, kept apart while this tree changes).
# Runs from another directory keep ../shared relative to the repository (MODELS and PEER
# override the models' directory and the peer's script).
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-3}
threads=${2:-2}
algo=${3:-count}
case "$algo" in
    count | ll) peer_algo=$algo; kflag=() ;;
    kb-rmw) peer_algo=kbuf-rmw; kflag=(--k 8) ;;
    kb-atomic32) peer_algo=kbuf-atomic; kflag=(--k 8) ;;
    *) echo "no peer counterpart for \`$algo\` (count, ll, kb-rmw, kb-atomic32)" >&2; exit 2 ;;
esac
lockstep=--no-lockstep
[ "${LOCKSTEP:-0}" = 1 ] && lockstep=
if [ -n "${FRAGRACE:-}" ]; then
    F=$FRAGRACE
else
    cargo build --release -q
    F=./target/release/fragrace
fi
M=${MODELS:-../shared/models}
PEER=${PEER:-../shared/peers/llvmpipe/oit.py}
python3 -c "import moderngl" 2>/dev/null || { echo "needs the llvmpipe peer's dependencies (see ci/bench.sh)" >&2; exit 1; }
median='import sys; v = sorted(float(x) for x in sys.argv[1:]); print(f"{v[len(v) // 2]:.2f}")'
for c in ${CASES:-dragon.obj.gz:512 dragon.obj.gz:2048 bunny.obj.gz:2048}; do
    mesh=${c%%:*}
    size=${c##*:}
    ratios=()
    cratios=()
    for r in $(seq "$rounds"); do
        theirs=$(python3 -c "import json,sys; print(round(json.load(sys.stdin)['median_ms'], 2))" <<< "$(LP_NUM_THREADS=$threads python3 "$PEER" "$M/$mesh" --algo "$peer_algo" "${kflag[@]}" --width "$size" --height "$size" --frames 15 --warmup 3 2>/dev/null | tail -1)")
        read -r ours checked < <(python3 -c "import json,sys; d=json.load(sys.stdin); print(round(d['median_ms'], 2), round(d['checked_median_ms'], 2))" <<< "$($F bench --obj "$M/$mesh" --algo "$algo" "${kflag[@]}" --threads "$threads" --width "$size" --height "$size" --frames 15 --warmup 3 $lockstep --json)")
        ratio=$(python3 -c "print(f'{$ours / $theirs:.2f}')")
        cratio=$(python3 -c "print(f'{$checked / $theirs:.2f}')")
        ratios+=("$ratio")
        cratios+=("$cratio")
        echo "$algo, $mesh @$size, pair $r: fragrace $ours ms / llvmpipe $theirs ms = $ratio (with fragrace's self-check after the frame: $checked ms, $cratio)"
    done
    echo "$algo, $mesh @$size: median ratio $(python3 -c "$median" "${ratios[@]}") over $rounds pairs (with the self-check: $(python3 -c "$median" "${cratios[@]}"))"
done
