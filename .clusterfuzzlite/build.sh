#!/bin/bash -eu
# Builds the cargo-fuzz targets of fuzz/ into $OUT, as ClusterFuzzLite and OSS-Fuzz run
# them (their image sets $SRC, $OUT and the sanitizer flags; the only sanitizer for Rust
# there is address, cargo fuzz's default).
#
# Locally, without docker (stable toolchain, no sanitizer; docs/fuzzing.md):
#   cargo install cargo-fuzz
#   RUSTC_BOOTSTRAP=1 CARGO_FUZZ_ARGS="--sanitizer none" OUT=/tmp/cflite-out \
#     bash .clusterfuzzlite/build.sh
# CARGO_FUZZ_ARGS: extra arguments of `cargo fuzz build` (none in the image).
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SRC_DIR="${SRC:+$SRC/fragrace}"
SRC_DIR="${SRC_DIR:-$here}"
[ -d "$SRC_DIR/fuzz" ] || SRC_DIR="$here"
OUT="${OUT:?set OUT to the directory the fuzzers go to}"
mkdir -p "$OUT"

cd "$SRC_DIR/fuzz"
# -O: release (the targets run the emulator; debug builds are 10-50x slower);
# --debug-assertions: keep the code's own checks, as the tests have them.
# shellcheck disable=SC2086
cargo fuzz build -O --debug-assertions ${CARGO_FUZZ_ARGS:-}

# The fuzz crate is its own workspace: its target directory is fuzz/target.
triple="$(rustc -vV | sed -n 's/^host: //p')"
bin_dir="$SRC_DIR/fuzz/target/$triple/release"
targets=$(cargo fuzz list)
for t in $targets; do
    cp "$bin_dir/$t" "$OUT/"
done
# The oracle target's inputs hold a scene and a schedule: let them be long from the start
# (fuzz/fuzz_targets/kernel_oracle.rs measured this finding the planted bug 2-4x sooner).
cat > "$OUT/kernel_oracle.options" <<'OPTIONS'
[libfuzzer]
len_control = 0
max_len = 256
OPTIONS
echo "built into $OUT: $(echo $targets | tr '\n' ' ')"
