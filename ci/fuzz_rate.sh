#!/usr/bin/env bash
# Fuzz campaign throughput per algorithm: `fragrace fuzz --algo ALGO --time TIME` (one job,
# the default scenes and sizes, nothing shrunk: --shrink-secs 0), and where the workers'
# time went (the campaign's `phases`), as markdown table rows for docs/performance.md.
# With BASE=PATH, each algorithm's campaign also runs under that binary just before this
# tree's (alternated, on these noisy machines), and the row gives both rates and their ratio.
# Usage: bash ci/fuzz_rate.sh [TIME] [ALGO...]   (defaults: 20s; kb-interlock ll kb-rmw
# count fab)
# Env: FRAGRACE=PATH runs that binary instead of this tree's release build; SCHEDULES=N
# passes --schedules N (default: the binary's default).
set -euo pipefail
cd "$(dirname "$0")/.."
time=${1:-20s}
shift || true
algos=("$@")
[ ${#algos[@]} -gt 0 ] || algos=(kb-interlock ll kb-rmw count fab)
if [ -n "${FRAGRACE:-}" ]; then
    F=$FRAGRACE
else
    cargo build --release -q
    F=./target/release/fragrace
fi
extra=()
[ -n "${SCHEDULES:-}" ] && extra=(--schedules "$SCHEDULES")
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
rate() {
    # Prints "EXECUTIONS/S PHASES" from a campaign's JSON state.
    python3 -c '
import json, sys
d = json.load(sys.stdin)
rate = d["executions"] / max(d["elapsed_s"], 1e-9)
p = d.get("phases") or {}
names = [("generate_s", "generation"), ("load_s", "load"), ("truth_s", "truth"),
         ("run_s", "run"), ("oracle_s", "oracle"), ("cases_s", "cases")]
total = sum(p.get(k, 0) for k, _ in names)
parts = ", ".join(f"{n} {100 * p.get(k, 0) / total:.0f} %" for k, n in names) if total else "-"
schedules = d.get("schedules", 1)
print(f"{rate:.1f}|{schedules}|{parts}")
'
}
echo "| algorithm | executions/s | schedules per scene | where the time goes |$([ -n "${BASE:-}" ] && echo " before (BASE) | ratio |")"
echo "|---|---|---|---|$([ -n "${BASE:-}" ] && echo "---|---|")"
for a in "${algos[@]}"; do
    before=
    if [ -n "${BASE:-}" ]; then
        rm -rf "$out/b"
        before=$(rate <<< "$("$BASE" fuzz --algo "$a" --time "$time" --shrink-secs 0 --json --out "$out/b")" | cut -d'|' -f1)
    fi
    rm -rf "$out/a"
    IFS='|' read -r ours schedules phases < <(rate <<< "$("$F" fuzz --algo "$a" --time "$time" --shrink-secs 0 "${extra[@]}" --json --out "$out/a")")
    if [ -n "$before" ]; then
        ratio=$(python3 -c "print(f'{$ours / $before:.1f}x')")
        echo "| $a | $ours | $schedules | $phases | $before | $ratio |"
    else
        echo "| $a | $ours | $schedules | $phases |"
    fi
done
