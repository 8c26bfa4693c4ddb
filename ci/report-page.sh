#!/usr/bin/env bash
# The report's page in a real browser: makes a quick report of every section and takes a
# headless-Chromium screenshot of its index.html (Debian's `chromium` package), opened from
# the file system. The screenshot is written to $OUT/page.png (OUT defaults to a temporary
# directory); look at it. Fails when chromium is not installed, saying so.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-$(mktemp -d)}"
browser="$(command -v chromium || command -v chromium-browser || true)"
if [ -z "$browser" ]; then
    echo "ci/report-page.sh: no chromium here (Debian: apt-get install chromium)" >&2
    exit 1
fi
cargo run --release -- report --paper all --quick --out "$OUT/report"
"$browser" --headless --no-sandbox --disable-gpu --window-size=1200,4000 \
    --screenshot="$OUT/page.png" "file://$(realpath "$OUT/report/index.html")"
echo "$OUT/page.png"
