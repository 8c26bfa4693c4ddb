#!/usr/bin/env bash
# Alternating A/B timing of two fragrace binaries: on a noisy machine the same command moves
# by 10-20 % between minutes, so two builds are compared in turns, not one after the other.
# Prints each run's median and minimum frame and its passes-alone median (ms). Minima are
# steadier than medians when the machine's neighbours are busy.
# Usage: bash ci/ab.sh BEFORE_BINARY AFTER_BINARY ROUNDS [fragrace bench flags...]
# Example (a build of an older commit in a worktree, then this tree):
#   git worktree add /tmp/base <rev> && (cd /tmp/base && CARGO_TARGET_DIR=/tmp/base-target cargo build --release)
#   bash ci/ab.sh /tmp/base-target/release/fragrace target/release/fragrace 3 \
#       --scene bunny --algo count --threads 2 --width 2048 --height 2048 --frames 20 --warmup 3 --no-lockstep
set -euo pipefail
[ $# -ge 3 ] || { sed -n 2,10p "$0" >&2; exit 2; }
before=$1 after=$2 rounds=$3
shift 3
for _ in $(seq "$rounds"); do
    for b in "$before" "$after"; do
        label=after
        [ "$b" = "$before" ] && label=before
        "$b" bench "$@" --json | python3 -c "import json,sys; d=json.load(sys.stdin); print('$label', round(d['median_ms'], 2), 'ms (min', round(d['min_ms'], 2), 'ms); passes alone', round(d['passes_median_ms'], 2), 'ms')"
    done
done
