#!/usr/bin/env bash
# Peak memory against its estimate, every algorithm: the figures behind src/budget.rs's
# model (and the bound tests/memory.rs keeps: peak within 1.5x of the estimate).
#
# Usage: bash ci/memory.sh VERB SCENE SIZE EXEC [more fragrace options]
#   e.g. bash ci/memory.sh check spheres 256 parallel
#        bash ci/memory.sh render teapot 160 scheduled --k 16
# Prints, per algorithm: measured peak (VmHWM), estimate, their ratio, fragments and their
# estimate. Builds the release binary first.
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 4 ] || { sed -n '5,9p' "$0"; exit 2; }
verb=$1 scene=$2 size=$3 exec=$4; shift 4
extra=("$@")
cargo build --release -q
F=target/release/fragrace
# NAME:OPTION,OPTION per algorithm: the shared options it reads (`list --json`, "reads").
for entry in $($F list --json | python3 -c 'import json,sys; print(" ".join(a["name"] + ":" + ",".join(a["reads"]) for a in json.load(sys.stdin)["algorithms"]))'); do
    a=${entry%%:*} reads=",${entry#*:},"
    # `--k N` and `--spin-cap N` only for the algorithms that read them (the others refuse
    # them).
    args=()
    set -- "${extra[@]}"
    while [ $# -gt 0 ]; do
        case "$1" in
            --k|--spin-cap)
                if [[ "$reads" == *",${1#--},"* ]]; then args+=("$1" "$2"); fi
                shift 2 ;;
            *) args+=("$1"); shift ;;
        esac
    done
    out=$($F "$verb" --scene "$scene" --algo "$a" --width "$size" --height "$size" --exec "$exec" --json "${args[@]}" 2>&1 | tail -n 1)
    python3 - "$a" "$out" <<'PY'
import json, sys
name, out = sys.argv[1], sys.argv[2]
try:
    v = json.loads(out)
    p, e = v["peak_rss_bytes"], v["memory_estimate_bytes"]
    print(f"{name:<24} peak {p/1e6:8.1f} MB  estimate {e/1e6:8.1f} MB  peak/estimate {p/e:.2f}  "
          f"fragments {v['fragments']} (estimated {v['fragments_estimate']})")
except Exception:
    print(f"{name:<24} {out}")
PY
done
