#!/usr/bin/env bash
# Runs every test: installs what is missing, runs `cargo test` (unit, physics,
# collision, solver, renderer and MPI tests), then runs the binary under
# mpirun on the bundled scenes and checks the outputs and determinism.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

cargo build --release --quiet
cargo test --release --no-fail-fast -- --test-threads=2

bin="${CARGO_TARGET_DIR:-target}"/release/rigidsim
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail=0
passed=0
check() { # name, command...
  local name=$1; shift
  if "$@"; then passed=$((passed + 1)); echo "ok: $name"; else fail=$((fail + 1)); echo "FAILED: $name"; fi
}
hash_of() { python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["state_hash"])' "$1/summary.json"; }

# Every bundled scene runs under mpirun -np 2 and writes both outputs.
for scene in scenes/*.toml; do
  name=$(basename "$scene" .toml)
  check "mpirun -np 2 $name" bash -c "mpirun -np 2 $bin $scene --duration 0.3 --no-render --no-progress --out $tmp/$name >/dev/null 2>&1 && \
    test -s $tmp/$name/summary.json && head -1 $tmp/$name/trajectory.csv | grep -qx 'time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz'"
done

# The same state hash on 1, 2 and 3 ranks, with every stage distributed.
for np in 1 2 3; do
  mpirun -np $np --oversubscribe $bin scenes/nuts_and_bolts.toml --force-distribute --no-render --no-progress \
    --duration 1.0 --out "$tmp/det$np" >/dev/null 2>&1 || true
done
check "state_hash equal on 1, 2, 3 ranks" bash -c "[ -n \"\$(cat $tmp/det1/summary.json 2>/dev/null)\" ] && \
  [ \"$(hash_of $tmp/det1 2>/dev/null)\" = \"$(hash_of $tmp/det2 2>/dev/null)\" ] && \
  [ \"$(hash_of $tmp/det1 2>/dev/null)\" = \"$(hash_of $tmp/det3 2>/dev/null)\" ]"

# The replay page (`rigidsim view`) in a real browser: headless Chromium with
# software WebGL opens the page of a small run and checks that a body is drawn
# where the trajectory puts it at t = 0 and at the end, that playing stops at
# the run's end time, that picking works, and that nothing is fetched or
# logged as an error. The committed bundle must be what viewer/src builds.
check "viewer bundle built from viewer/src" bash -c "cd viewer && node build.mjs --check"
check "replay page in headless chromium" bash -c "$bin scenes/render_check.toml --no-render --no-progress --out $tmp/replay >/dev/null 2>&1 && \
  $bin view scenes/render_check.toml $tmp/replay >/dev/null && \
  node viewer/test/replay_in_chromium.mjs --page $tmp/replay/replay.html --run $tmp/replay --body 1"

# Every benchmark once on a tiny setting, so none can rot (timings are not checked).
check "bench_accuracy --tiny" bash scripts/bench_accuracy.sh --tiny
check "bench_scaling --tiny" bash scripts/bench_scaling.sh --tiny
check "bench_peer --tiny" bash scripts/bench_peer.sh --tiny
check "bench_pour --tiny" bash scripts/bench_pour.sh --tiny
check "cargo bench broadphase/vclip/lcp compile and run" bash -c "cargo bench --quiet --bench broadphase -- --tiny >/dev/null"

echo "scripts/test.sh: $passed passed, $fail failed"
[ "$fail" -eq 0 ]
