#!/usr/bin/env bash
# A peer on the same work (issue 7 §3): rigidsim and Rapier (rapier3d-f64,
# its recommended settings) on the same exact cases and on the nuts and bolts
# falling to rest, in the same run. Builds bench/peer, a standalone crate: the
# simulator never depends on Rapier. Writes peer.csv, peer_scenes.csv,
# peer.md (side-by-side tables with ratios) and peer_<case>.png under
# bench/results/<machine>/ (BENCH_MACHINE, default <host>-<cores>cpu).
#
# Usage: scripts/bench_peer.sh [--tiny] [--reps N] [--counts 20,50] [--out DIR]
#   --tiny (or TINY=1): a few steps of everything into target/bench-tiny/ (CI).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

args=()
for a in "$@"; do args+=("$a"); done
if [ "${TINY:-0}" = 1 ]; then args+=(--tiny); fi
export BENCH_MACHINE=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
# The root target folder is shared: crates common to both builds compile once.
cargo build --release --quiet --manifest-path bench/peer/Cargo.toml --target-dir "${CARGO_TARGET_DIR:-target}"
"${CARGO_TARGET_DIR:-target}"/release/rigidsim-peer "${args[@]}"
