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

# The live page (`rigidsim live`) in a real browser: headless Chromium opens
# the page of a live run, grabs the cube with the mouse and drags it up (the
# states show it rising), lets go and stops the run from the page, which then
# ends with its outputs (docs/live.md).
live_page() {
  "$bin" live scenes/render_check.toml --port 0 --no-render --out "$tmp/live" >"$tmp/live.url" 2>"$tmp/live.log" &
  local pid=$! url=""
  for _ in $(seq 100); do
    url=$(head -1 "$tmp/live.url" 2>/dev/null || true)
    [ -n "$url" ] && break
    sleep 0.1
  done
  if node viewer/test/live_in_chromium.mjs --url "$url" --body 1 && wait "$pid" &&
    grep -q '"end_reason": "stopped"' "$tmp/live/summary.json"; then
    return 0
  fi
  kill "$pid" 2>/dev/null || true
  cat "$tmp/live.log"
  return 1
}
check "live page in headless chromium" live_page

# A lab in a box (scripts/lab.sh): 2 "PCs", mpirun over ssh and TCP only,
# every stage distributed: the same state hash as one rank, and each rank
# reports its own host. Then a PC's processes killed, and a PC's cable
# pulled, mid-run: the job ends within 15 s naming the PC and its rank, the
# trajectory written so far is kept, and the lab leaves nothing behind.
if why=$(bash scripts/lab.sh --check 2>&1); then
  lab() { bash scripts/lab.sh --name rsci "$@"; }
  source scripts/crowd.sh
  crowd_of 200 >"$tmp/crowd200.toml"
  lab --hosts 2 --link 100mbit scenes/nuts_and_bolts.toml --force-distribute --no-render --no-progress \
    --duration 1.0 --out "$tmp/lab2" >"$tmp/lab2.log" 2>&1 || true
  same_as_one_rank() { # the 2-PC run's hash is det1's; ranks on pc1 and pc2; bytes crossed the link
    [ -s "$tmp/det1/summary.json" ] && [ -s "$tmp/lab2/summary.json" ] &&
      [ "$(hash_of "$tmp/lab2")" = "$(hash_of "$tmp/det1")" ] &&
      grep -q "^rigidsim: ranks by host: pc1: 0; pc2: 1$" "$tmp/lab2.log" &&
      python3 - "$tmp/lab2/summary.json" <<'PY' || { cat "$tmp/lab2.log"; false; }
import json, sys
ranks = json.load(open(sys.argv[1]))["per_rank"]
assert [r["host"] for r in ranks] == ["pc1", "pc2"], ranks
assert ranks[1]["bytes_received_per_frame"] > 0, ranks
# 100 Mbit/s is 12.5 MB/s (TCP and busy cores take some of it); shared memory is > 100 MB/s.
assert 1e6 < ranks[1]["link_bytes_per_s"] < 5e7, ranks
PY
  }
  check "lab: 2 PCs over ssh and TCP, state_hash as on 1 rank" same_as_one_rank
  ended_in_time() { # log, PC, rank: the job failed within 15 s of the fault, naming both
    grep -q "pc$2 (10.250.0.$2) ran rank(s) $3" "$1" &&
      awk '/the job ended .* after the fault/ { s = $5 } END { exit !(s != "" && s < 15) }' "$1" &&
      grep -q "exit status [1-9]" "$1" && [ -s "$(dirname "$1")/fault/trajectory.csv" ] &&
      ! ip netns list | grep -q '^rsci-' || { cat "$1"; false; }
  }
  mkdir -p "$tmp/kill" "$tmp/down"
  lab --hosts 2 --fault kill:2@3 "$tmp/crowd200.toml" --no-render --no-progress --duration 60 \
    --out "$tmp/kill/fault" >"$tmp/kill/log" 2>&1 || true
  check "lab: a PC's processes killed mid-run end the job within 15 s, naming it" ended_in_time "$tmp/kill/log" 2 1
  lab --hosts 3 --fault down:3@3 "$tmp/crowd200.toml" --no-render --no-progress --duration 60 \
    --out "$tmp/down/fault" >"$tmp/down/log" 2>&1 || true
  check "lab: a PC's cable pulled mid-run ends the job within 15 s, naming it" ended_in_time "$tmp/down/log" 3 2
  check "bench_network --tiny" bash scripts/bench_network.sh --tiny
else
  echo "skipped: lab tests (2 PCs over ssh and TCP, faults across hosts, bench_network --tiny): $why"
fi

# Every benchmark once on a tiny setting, so none can rot (timings are not checked).
check "bench_accuracy --tiny" bash scripts/bench_accuracy.sh --tiny
check "bench_scaling --tiny" bash scripts/bench_scaling.sh --tiny
check "bench_peer --tiny" bash scripts/bench_peer.sh --tiny
check "bench_pour --tiny" bash scripts/bench_pour.sh --tiny
check "bench_dial --tiny" bash scripts/bench_dial.sh --tiny
check "bench_many_ranks --tiny" bash scripts/bench_many_ranks.sh --tiny
check "bench_predict --tiny" bash scripts/bench_predict.sh --tiny
check "device_many_ranks check (Open MPI from .ompi alone)" bash scripts/device_many_ranks.sh check
check "bench_instructions --tiny" bash scripts/bench_instructions.sh --tiny
check "cargo bench broadphase/vclip/lcp compile and run" bash -c "cargo bench --quiet --bench broadphase -- --tiny >/dev/null"

echo "scripts/test.sh: $passed passed, $fail failed"
[ "$fail" -eq 0 ]
