#!/usr/bin/env bash
# Runs the main job: installs what is missing, builds, and runs a scene under
# MPI.  Usage: scripts/run.sh [SCENE] [rigidsim options...]
#          or: scripts/run.sh live [SCENE] [rigidsim live options...]
# (the scene paced to the wall clock; open the printed URL in a browser to
# see it and move its bodies with the mouse; Ctrl-C or the page's stop ends it).
# Ranks: RANKS=5 scripts/run.sh ... (default 3: coordinator, worker, renderer).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

command=()
if [ "${1:-}" = live ]; then
  command=(live)
  shift
fi
scene="${1:-scenes/nuts_and_bolts.toml}"
shift || true
cargo build --release --quiet
ranks="${RANKS:-3}"
exec mpirun -np "$ranks" --oversubscribe ${HOSTFILE:+--hostfile "$HOSTFILE"} \
  "${CARGO_TARGET_DIR:-target}"/release/rigidsim "${command[@]}" "$scene" "$@"
