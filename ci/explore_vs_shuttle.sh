#!/usr/bin/env bash
# Side by side, alternated: the scheduled executor's executions per second on the
# linked-list push of `cargo bench --bench explore` (4 invocations on one pixel, hazard
# detector and schedule recording on) against shuttle's PCT scheduler on the same push
# (../shared/peers/loom-shuttle: `shuttle-pct 4`, 100,000 schedules). On these shared
# machines a minute apart can mean 20 %, so each round runs the peer, then fragrace, and
# prints both and their ratios; the summary is the median of the rounds' ratios per policy
# (the acceptance bar of issue 27: 1 M executions/s and 10x shuttle's PCT).
# The peer is copied to target/peers/loom-shuttle and built there (its directory is
# read-only; cargo fetches loom and shuttle from crates.io the first time).
# Usage: bash ci/explore_vs_shuttle.sh [ROUNDS]   (default 5)
# Env: PEER (default ../shared/peers/loom-shuttle, relative to the repository),
# THREADS (the peer's invocations, default 4: the bench's model).
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-5}
threads=${THREADS:-4}
peer_src=${PEER:-../shared/peers/loom-shuttle}
[ -f "$peer_src/Cargo.toml" ] || { echo "no peer at $peer_src (set PEER)" >&2; exit 1; }
peer_dir=target/peers/loom-shuttle
mkdir -p "$peer_dir"
cp -r "$peer_src/Cargo.toml" "$peer_src/src" "$peer_dir/"
chmod -R u+w "$peer_dir"
# A package of its own, not a member of this workspace (it sits under target/).
printf '\n[workspace]\n' >> "$peer_dir/Cargo.toml"
cargo build --release -q --manifest-path "$peer_dir/Cargo.toml" --target-dir "$peer_dir/target"
peer_bin=$peer_dir/target/release/loom-shuttle-llpush
# Build the bench once, so that every round times the same binary and no build.
cargo bench --bench explore --no-run -q 2>/dev/null
log=$(mktemp)
trap 'rm -f "$log"' EXIT
for r in $(seq "$rounds"); do
    # shuttle prints `shuttle-pct threads=4 iters=100000 time=... per_iter=9.7us`.
    out=$("$peer_bin" shuttle-pct "$threads")
    peer_us=$(sed -E 's/.*per_iter=([0-9.]+)us.*/\1/' <<< "$out")
    peer_rate=$(python3 -c "print(round(1e6 / $peer_us))")
    # criterion prints `thrpt:  [LOW Kelem/s MID Kelem/s HIGH Kelem/s]` per policy, in the
    # bench's order (random, then pct:2).
    bench=$(cargo bench -q --bench explore -- --warm-up-time 1 --measurement-time 3 --noplot 2>/dev/null)
    rates=$(python3 -c '
import re, sys
unit = {"elem/s": 1, "Kelem/s": 1e3, "Melem/s": 1e6, "Gelem/s": 1e9}
name = None
for line in sys.stdin:
    m = re.match(r"^(ll-push-4/\S+)", line)
    if m:
        name = m.group(1).split("/")[1]
    t = re.search(r"thrpt:\s+\[\S+ \S+ (\S+) (\S+) ", line)
    if t and name:
        print(name, round(float(t.group(1)) * unit[t.group(2)]))
        name = None
' <<< "$bench")
    while read -r policy rate; do
        ratio=$(python3 -c "print(f'{$rate / $peer_rate:.2f}')")
        echo "round $r: fragrace $policy $rate executions/s, shuttle pct $peer_rate/s: ${ratio}x"
        echo "$policy $rate $peer_rate" >> "$log"
    done <<< "$rates"
done
python3 - "$log" <<'PY'
import statistics, sys
runs = {}
for line in open(sys.argv[1]):
    policy, ours, theirs = line.split()
    runs.setdefault(policy, []).append((float(ours), float(theirs)))
for policy, r in runs.items():
    print(f"{policy}: median {statistics.median(o for o, _ in r) / 1e3:.0f} K executions/s, "
          f"shuttle pct median {statistics.median(t for _, t in r) / 1e3:.0f} K/s, "
          f"median ratio {statistics.median(o / t for o, t in r):.2f}x over {len(r)} rounds")
PY
