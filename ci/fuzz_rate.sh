#!/usr/bin/env bash
# Fuzz campaign throughput per algorithm: `fragrace fuzz --algo ALGO --time TIME` (the
# binary's default jobs unless JOBS is set, the default scenes and sizes, nothing shrunk:
# --shrink-secs 0), and where the workers' time went (the campaign's `phases`), as markdown
# table rows for docs/performance.md. Each row says how many jobs ran, their total rate and
# the rate per job.
# With BASE=PATH, each algorithm's campaign also runs under that binary just before this
# tree's (alternated, on these noisy machines), and the row gives both rates and their ratio.
# Usage: bash ci/fuzz_rate.sh [TIME] [ALGO...]   (defaults: 20s; kb-interlock ll kb-rmw
# count fab)
# Env: FRAGRACE=PATH runs that binary instead of this tree's release build; SCHEDULES=N
# passes --schedules N (default: the binary's default); JOBS=N passes --jobs N to both
# binaries (default: each binary's default: 1 before 2026-11-28, the available parallelism
# since); ITERATIONS=N runs N iterations
# (scenes) instead of TIME, the same work for both binaries. Each rate is also given per
# second of CPU time (user + system, GNU time), which a loaded machine disturbs less than
# the wall clock (its other jobs take the wall time, not the CPU time).
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
jobs=()
[ -n "${JOBS:-}" ] && jobs=(--jobs "$JOBS")
budget=(--time "$time")
[ -n "${ITERATIONS:-}" ] && budget=(--iterations "$ITERATIONS")
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
campaign() {
    # campaign BINARY DIR [FLAGS...]: the campaign's JSON state, with "cpu_s" added.
    local bin=$1 dir=$2
    shift 2
    rm -rf "$dir"
    /usr/bin/time -f '%U %S' -o "$out/cpu" "$bin" fuzz --algo "$a" "${budget[@]}" --shrink-secs 0 "${jobs[@]}" "$@" --json --out "$dir" > "$out/state.json"
    python3 -c '
import json, sys
d = json.load(open(sys.argv[1]))
d["cpu_s"] = sum(map(float, open(sys.argv[2]).read().split()[-2:]))
print(json.dumps(d))
' "$out/state.json" "$out/cpu"
}
rate() {
    # Prints "JOBS|EXECUTIONS/S|PER JOB|PER CPU S|SCHEDULES|PHASES" from a campaign's JSON
    # state (a state without `jobs` is from a binary that ran one job by default).
    python3 -c '
import json, sys
d = json.load(sys.stdin)
rate = d["executions"] / max(d["elapsed_s"], 1e-9)
cpu = d["executions"] / d["cpu_s"] if d["cpu_s"] >= 0.5 else float("nan")  # (time rounds to 0.01 s)
p = d.get("phases") or {}
names = [("generate_s", "generation"), ("load_s", "load"), ("truth_s", "truth"),
         ("run_s", "run"), ("oracle_s", "oracle"), ("cases_s", "cases")]
total = sum(p.get(k, 0) for k, _ in names)
parts = ", ".join(f"{n} {100 * p.get(k, 0) / total:.0f} %" for k, n in names) if total else "-"
schedules = d.get("schedules", 1)
jobs = d.get("jobs", 1)
print(f"{jobs}|{rate:.1f}|{rate / jobs:.1f}|{cpu:.1f}|{schedules}|{parts}")
'
}
echo "| algorithm | jobs | executions/s | per job | per CPU second | schedules per scene | where the time goes |$([ -n "${BASE:-}" ] && echo " before (BASE): jobs | executions/s | per CPU second | ratio (CPU) |")"
echo "|---|---|---|---|---|---|---|$([ -n "${BASE:-}" ] && echo "---|---|---|---|")"
for a in "${algos[@]}"; do
    before=
    if [ -n "${BASE:-}" ]; then
        IFS='|' read -r before_jobs before _ before_cpu _ _ < <(rate <<< "$(campaign "$BASE" "$out/b")")
    fi
    IFS='|' read -r ours_jobs ours per_job ours_cpu schedules phases < <(rate <<< "$(campaign "$F" "$out/a" "${extra[@]}")")
    if [ -n "$before" ]; then
        ratio=$(python3 -c "print(f'{$ours / $before:.2f}x ({float(\"$ours_cpu\") / float(\"$before_cpu\"):.2f}x)')")
        echo "| $a | $ours_jobs | $ours | $per_job | $ours_cpu | $schedules | $phases | $before_jobs | $before | $before_cpu | $ratio |"
    else
        echo "| $a | $ours_jobs | $ours | $per_job | $ours_cpu | $schedules | $phases |"
    fi
done
