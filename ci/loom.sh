#!/usr/bin/env bash
# Runs the loom models with a pinned preemption bound (set in each model) and prints the
# time each suite took. Separate target dir: --cfg loom changes every crate's build.
set -euo pipefail
cd "$(dirname "$0")/.."
export RUSTFLAGS="--cfg loom"
export LOOM_MAX_PREEMPTIONS=${LOOM_MAX_PREEMPTIONS:-2}
for suite in "-p fragrace-emu --test loom" "-p fragrace-kernels --test loom" "-p fragrace-kernels --test loom_racebench"; do
    if [ "$suite" = "-p fragrace-kernels --test loom" ] && [ ! -f kernels/tests/loom/main.rs ]; then continue; fi
    t0=$SECONDS
    # shellcheck disable=SC2086
    cargo test --release --target-dir target/loom $suite
    echo "loom $suite: $((SECONDS - t0)) s"
done
