#!/usr/bin/env bash
# The image-error table of docs/algorithms.md ("Fragment merging"): image EPR and PSNR
# against the exact composite of the truth, per algorithm and k, on hairball at 128x128
# (ordered executor; the merging algorithms give the same image under every executor).
# Usage: bash ci/merging_table.sh [SCENE] [SIZE] [THICKNESS] [AZIMUTH]   (THICKNESS as --thickness:
# 2xP, 100xP, 0.01; SCENE a built-in scene or an OBJ path, e.g. ../shared/models/dragon.obj.gz;
# AZIMUTH in degrees, default 0)
set -euo pipefail
scene=${1:-hairball}
size=${2:-128}
thickness=${3:-2xP}
azimuth=${4:-0}
cargo build --release -q
bin=./target/release/fragrace
case "$scene" in
  *.obj | *.obj.gz) source_args=(--obj "$scene") ;;
  *) source_args=(--scene "$scene") ;;
esac
echo "| algorithm | k | image EPR | PSNR (dB) | max channel difference |"
echo "|---|---|---|---|---|"
for algo in kb-rmw kplus kb-ofm skb-ofm dfb-sfm; do
  for k in 4 8 16; do
    $bin check "${source_args[@]}" --algo "$algo" --k "$k" --exec ordered \
      --thickness "$thickness" --azimuth "$azimuth" --width "$size" --height "$size" --json |
      python3 -c 'import json, sys
d = json.load(sys.stdin)
im = d["image"]
psnr = "inf" if im["psnr"] is None else "%.2f" % im["psnr"]
print("| `%s` | %d | %.4f | %s | %.4f |" % (d["algo"], d["k"], im["image_epr"], psnr, im["max_diff"]))'
  done
done
