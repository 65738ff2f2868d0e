#!/usr/bin/env bash
# Run time against error (issue 7 §1): every exact case swept over the time
# step, single rank, release build; CSV, Markdown tables and log-log PNG plots
# under bench/results/<machine>/ (BENCH_MACHINE, default <host>-<cores>cpu).
#
# Usage: scripts/bench_accuracy.sh [--tiny] [bench options...]
#   --tiny (or TINY=1): a few steps of each case into target/bench-tiny/ (CI).
#   Options go to benches/accuracy.rs: --reps N (default 5), --dts 1e-3,1e-2,
#   --cases projectile,bouncing_cube, --out DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

args=()
for a in "$@"; do args+=("$a"); done
if [ "${TINY:-0}" = 1 ]; then args+=(--tiny); fi
export BENCH_MACHINE=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
cargo bench --quiet --bench accuracy -- "${args[@]}"
