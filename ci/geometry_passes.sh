#!/usr/bin/env bash
# Geometry passes per frame of the peelers and k-buffers (the analogue of Table 2 of
# "Efficient Depth Peeling via Bucket Sort"), with the formula from the maximum depth
# complexity D, on bunny, teapot, the 871K dragon and hairball at 512 x 512.
# Usage: bash ci/geometry_passes.sh [DRAGON.obj.gz]   (default ../shared/models/dragon.obj.gz)
# Prints a markdown table; needs a release build (cargo build --release).
set -euo pipefail
F=${FRAGRACE:-./target/release/fragrace}
DRAGON=${1:-../shared/models/dragon.obj.gz}
ALGOS="f2b:256 f2b2:256 dual:8 bdp:32 bdp2:64 adp:1024 kb-rmw:8 kb-multipass:8"
echo "| scene | D | $(for a in $ALGOS; do printf '%s | ' "${a%%:*}"; done)"
echo "|---|---|$(for a in $ALGOS; do printf -- '---|'; done)"
for scene in bunny teapot dragon hairball; do
  if [ "$scene" = dragon ]; then src=(--obj "$DRAGON"); else src=(--scene "$scene"); fi
  row="" d=""
  for a in $ALGOS; do
    algo=${a%%:*} k=${a##*:}
    j=$($F check "${src[@]}" --algo "$algo" --k "$k" --width 512 --height 512 --exec parallel --memory-limit 24G --json)
    g=$(echo "$j" | python3 -c 'import json,sys; v=json.load(sys.stdin); print(v["geometry_passes"], v["passes"]["fullscreen"], v["max_depth_complexity"])')
    set -- $g
    d=$3
    row+="$1 | "
  done
  echo "| $scene | $d | $row"
done
