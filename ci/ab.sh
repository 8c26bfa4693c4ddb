#!/usr/bin/env bash
# Alternating A/B timing of two fragrace binaries: on a noisy machine the same command moves
# by 10-20 % between minutes, so two builds are compared in turns, not one after the other.
# Prints each run's median and minimum frame, its passes-alone median and each pass's median
# (ms, in the order `bench` lists them), then a summary per binary: the median of the run
# medians, of the passes-alone medians and of each pass's medians, and the minimum of
# the minima (minima are steadier than medians when the machine's neighbours are busy), and
# in how many rounds AFTER's median beat BEFORE's.
# Usage: bash ci/ab.sh BEFORE_BINARY AFTER_BINARY ROUNDS [fragrace bench flags...]
# Example (a build of an older commit in a worktree, then this tree):
#   git worktree add /tmp/base <rev> && (cd /tmp/base && CARGO_TARGET_DIR=/tmp/base-target cargo build --release)
#   bash ci/ab.sh /tmp/base-target/release/fragrace target/release/fragrace 3 \
#       --scene bunny --algo count --threads 2 --width 2048 --height 2048 --frames 20 --warmup 3 --no-lockstep
set -euo pipefail
[ $# -ge 3 ] || { sed -n 2,12p "$0" >&2; exit 2; }
before=$1 after=$2 rounds=$3
shift 3
log=$(mktemp)
trap 'rm -f "$log"' EXIT
for _ in $(seq "$rounds"); do
    for b in "$before" "$after"; do
        label=after
        [ "$b" = "$before" ] && label=before
        python3 -c "import json,sys; d=json.load(sys.stdin); print('$label', round(d['median_ms'], 2), round(d['min_ms'], 2), round(d['passes_median_ms'], 2), ' '.join(str(round(p['median_ms'], 2)) for p in d['phases']))" <<< "$("$b" bench "$@" --json 2>/dev/null)" | tee -a "$log" | awk '{printf "%s %s ms (min %s ms); passes alone %s ms; each pass", $1, $2, $3, $4; for (i = 5; i <= NF; i++) printf " %s", $i; print " ms"}'
    done
done
python3 - "$log" <<'PY'
import statistics, sys
runs = {"before": [], "after": []}
for line in open(sys.argv[1]):
    label, med, mn, passes, *each = line.split()
    runs[label].append((float(med), float(mn), float(passes), [float(v) for v in each]))
for label, r in runs.items():
    each = " / ".join(f"{statistics.median(c):.2f}" for c in zip(*(x[3] for x in r)))
    print(f"{label}: median of medians {statistics.median(x[0] for x in r):.2f} ms, "
          f"of passes {statistics.median(x[2] for x in r):.2f} ms (each pass: {each} ms), "
          f"min of minima {min(x[1] for x in r):.2f} ms")
wins = sum(a[0] < b[0] for b, a in zip(runs["before"], runs["after"]))
print(f"after's median below before's in {wins} of {len(runs['after'])} rounds")
PY
