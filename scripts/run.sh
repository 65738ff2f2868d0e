#!/usr/bin/env bash
# Runs the main job: installs what is missing, builds, and runs a scene under
# MPI.  Usage: scripts/run.sh [SCENE] [rigidsim options...]
# Ranks: RANKS=5 scripts/run.sh ... (default 3: coordinator, worker, renderer).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

scene="${1:-scenes/nuts_and_bolts.toml}"
shift || true
cargo build --release --quiet
ranks="${RANKS:-3}"
exec mpirun -np "$ranks" --oversubscribe ${HOSTFILE:+--hostfile "$HOSTFILE"} \
  "${CARGO_TARGET_DIR:-target}"/release/rigidsim "$scene" "$@"
