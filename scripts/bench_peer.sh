#!/usr/bin/env bash
# Peers on the same work (issue 22): rigidsim, Rapier, Bullet and MuJoCo on
# the exact cases of docs/accuracy.md and on pours of nuts and bolts, in one
# sitting, each measured by one yardstick.
#
# Every engine runs as its own program on the bodies `rigidsim export`
# writes, and writes rigidsim's trajectory.csv (a probe run) and a record of
# its timed runs; bench/peer's `yardstick` measures every trajectory with the
# same exact answers and the same overlap oracle. The engines:
#   rigidsim               the CLI, one rank (and `rigidsim_np2`: mpirun -np 2, pours)
#   rapier_default/_tuned  bench/peer_rapier (rapier3d-f64 0.36.1): defaults, and
#                          length_unit set to the bodies' size; `rapier_tuned_parallel`:
#                          the `parallel` feature on 2 threads (pours)
#   bullet_dantzig/_default  bench/peer_py (pybullet): CONSTRAINT_SOLVER_LCP_DANTZIG, and default
#   mujoco_default/_hard     bench/peer_py (mujoco): default, and elliptic cones,
#                          impratio 10, noslip_iterations 10
# pybullet and mujoco come from PyPI as binary wheels into a virtual
# environment this script creates ($PEER_VENV, default $CARGO_TARGET_DIR/peer-venv); where one
# cannot be installed, one line says which and why and the others still run.
#
# Usage: scripts/bench_peer.sh [--tiny] [--reps N] [--pour-reps N] [--dts 1e-3,1e-2]
#                              [--counts 50,200] [--pour-time S] [--cap ENGINE@COUNT=S ...]
#                              [--engines a,b] [--out DIR]
#   --tiny (or TINY=1): a few steps of every engine into target/bench-tiny/ (CI).
#   --cap rapier_default@200=2: that engine simulates only 2 s of that pour
#     (compared per simulated second).
# Output (bench/results/<machine>/, BENCH_MACHINE, default <host>-<cores>cpu):
#   peers.jsonl (one line per run), peers.csv, peers.md, peers_mapping.txt,
#   peers_<case>.png; trajectories are kept only with KEEP_RUNS=1.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

tiny=${TINY:-0} reps=3 pour_reps=1 dts=1e-3,3e-3,1e-2 counts=50,200 pour_time=5 out="" engines=""
caps=()
while [ $# -gt 0 ]; do
  case $1 in
    --tiny) tiny=1 ;;
    --reps) reps=$2; shift ;;
    --pour-reps) pour_reps=$2; shift ;;
    --dts) dts=$2; shift ;;
    --counts) counts=$2; shift ;;
    --pour-time) pour_time=$2; shift ;;
    --cap) caps+=("$2"); shift ;;
    --engines) engines=$2; shift ;;
    --out) out=$2; shift ;;
    *) echo "bench_peer: unknown argument $1" >&2; exit 2 ;;
  esac
  shift
done
machine=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
export BENCH_MACHINE=$machine
target=${CARGO_TARGET_DIR:-target}
if [ "$tiny" = 1 ]; then
  reps=1 pour_reps=1 dts=1e-2 counts=3 pour_time=0.05
  out=${out:-target/bench-tiny/$machine}
fi
out=${out:-bench/results/$machine}
mkdir -p "$out"
work=$(mktemp -d)
if [ "${KEEP_RUNS:-0}" = 1 ]; then echo "bench_peer: runs kept in $work"; else trap 'rm -rf "$work"' EXIT; fi
started=$(date +%s)
root=$(pwd)

# Builds: the simulator, the yardstick, Rapier twice (serial, and with its
# `parallel` feature; both variants stay cached in the one target folder).
cargo build --release --quiet
cargo build --release --quiet --manifest-path bench/peer/Cargo.toml --target-dir "$target"
cargo build --release --quiet --manifest-path bench/peer_rapier/Cargo.toml --target-dir "$target" --features parallel
cp "$target/release/rapier-peer" "$target/release/rapier-peer-parallel"
cargo build --release --quiet --manifest-path bench/peer_rapier/Cargo.toml --target-dir "$target"
rigidsim=$target/release/rigidsim
yardstick=$target/release/yardstick

# The Python peers' environment: binary wheels only, pinned versions that
# install on Debian 12's Python 3.11 (and on later Pythons with wheels).
venv=${PEER_VENV:-$target/peer-venv}
[[ $venv = /* ]] || venv=$root/$venv
have_bullet=0 have_mujoco=0
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv" >/dev/null 2>&1 || rm -rf "$venv"
fi
if [ -x "$venv/bin/python" ]; then
  pipq() { "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --only-binary :all: "$@" 2>"$work/pip.err"; }
  why() { grep -m1 -E 'ERROR|No matching' "$work/pip.err" | cut -c1-160; }
  if ! "$venv/bin/python" -c 'import numpy' 2>/dev/null && ! pipq numpy==2.4.6; then
    echo "bench_peer: bullet and mujoco skipped: numpy 2.4.6 could not be installed as a binary wheel (pip: $(why))"
  else
    if "$venv/bin/python" -c 'import pybullet' 2>/dev/null || pipq pybullet==3.2.7; then have_bullet=1
    else echo "bench_peer: bullet skipped: pybullet 3.2.7 could not be installed as a binary wheel (pip: $(why))"; fi
    if "$venv/bin/python" -c 'import mujoco' 2>/dev/null || pipq mujoco==3.3.7; then have_mujoco=1
    else echo "bench_peer: mujoco skipped: mujoco 3.3.7 could not be installed as a binary wheel (pip: $(why))"; fi
  fi
else
  echo "bench_peer: bullet and mujoco skipped: python3 cannot create a virtual environment (Debian: apt-get install python3-venv)"
fi

case_engines="rigidsim rapier_default rapier_tuned bullet_dantzig bullet_default mujoco_default mujoco_hard"
pour_engines="rigidsim rigidsim_np2 rapier_default rapier_tuned rapier_tuned_parallel bullet_dantzig bullet_default mujoco_default mujoco_hard"
wanted() { # engine: in --engines (if given) and installed
  [ -z "$engines" ] || [[ ",$engines," == *",$1,"* ]] || return 1
  case $1 in bullet_*) [ $have_bullet = 1 ] ;; mujoco_*) [ $have_mujoco = 1 ] ;; *) true ;; esac
}

# run ENGINE TOML BODIES DURATION SAMPLE_EVERY_STEPS FRAME REPS DIR: the probe
# trajectory DIR/trajectory.csv and the record DIR/record.json.
run() {
  local engine=$1 toml=$2 bodies=$3 dur=$4 every=$5 frame=$6 n=$7 dir=$8
  mkdir -p "$dir"
  case $engine in
    rigidsim|rigidsim_np2)
      # The trajectory from the CLI. Timed runs: one rank in process, timed
      # like every other engine (`yardstick time`: the step call only); two
      # ranks through mpirun, from summary.json's wall_time_s (the whole
      # frame loop, with its trajectory rows: one row at the end here).
      local launch=()
      [ "$engine" = rigidsim_np2 ] && launch=(mpirun -np 2)
      local dt; dt=$(python3 -c 'import json,sys; print(repr(json.load(open(sys.argv[1]))["world"]["dt"]))' "$bodies")
      local sample; sample=$(python3 -c "print(repr($dt * $every))")
      "${launch[@]}" "$rigidsim" "$toml" --duration "$dur" --no-render --no-progress \
        --sample-every "$sample" --out "$dir/probe" >"$dir/log" 2>&1 || { cat "$dir/log"; return 1; }
      mv "$dir/probe/trajectory.csv" "$dir/trajectory.csv"
      if [ "$engine" = rigidsim ]; then
        "$yardstick" time "$toml" --duration "$dur" --frame "$frame" --reps "$n" --record "$dir/record.json"
        return
      fi
      for k in $(seq "$n"); do
        "${launch[@]}" "$rigidsim" "$toml" --duration "$dur" --no-render --no-progress \
          --sample-every "$dur" --out "$dir/timed$k" >"$dir/log" 2>&1 || { cat "$dir/log"; return 1; }
      done
      python3 - "$dir" "$n" "$engine" <<'EOF'
import json, sys
d, n, engine = sys.argv[1], int(sys.argv[2]), sys.argv[3]
s = [json.load(open(f"{d}/timed{k}/summary.json")) for k in range(1, n + 1)]
json.dump({"engine": engine, "version": "rigidsim (this checkout), mpirun -np %d" % s[0]["ranks"],
           "steps": s[0]["steps"], "dt": s[0]["sim_time_s"] / max(1, s[0]["steps"]),
           "sim_time_s": s[0]["sim_time_s"], "walls_s": [x["wall_time_s"] for x in s],
           "worst_frames_s": [x["worst_frame_s"] for x in s], "frame_interval_s": s[0]["frame_interval_s"],
           "threads": s[0]["ranks"], "mapping": {"rule": "the scene's own"}}, open(f"{d}/record.json", "w"))
EOF
      ;;
    rapier_default|rapier_tuned)
      "$target/release/rapier-peer" "${engine#rapier_}" "$bodies" --duration "$dur" --sample-every "$every" \
        --frame "$frame" --reps "$n" --trajectory "$dir/trajectory.csv" --record "$dir/record.json" ;;
    rapier_tuned_parallel)
      RAYON_NUM_THREADS=2 "$target/release/rapier-peer-parallel" tuned "$bodies" --duration "$dur" \
        --sample-every "$every" --frame "$frame" --reps "$n" --trajectory "$dir/trajectory.csv" --record "$dir/record.json" ;;
    bullet_*|mujoco_*)
      local e=${engine%%_*} c=${engine#*_}
      # In the run's folder: MuJoCo writes MUJOCO_LOG.TXT where it runs.
      (cd "$dir" && "$venv/bin/python" "$root/bench/peer_py/peer.py" "$e" "$c" "$bodies" --duration "$dur" \
        --sample-every "$every" --frame "$frame" --reps "$n" --trajectory trajectory.csv --record record.json >/dev/null) ;;
  esac
}

jsonl=$out/peers.jsonl
[ "$tiny" = 1 ] && jsonl=$work/peers.jsonl
: >"$jsonl"
failed=0
measure() { # engine dir bodies what...
  local engine=$1 dir=$2 bodies=$3; shift 3
  if ! "$yardstick" measure --engine "$engine" --bodies "$bodies" --trajectory "$dir/trajectory.csv" \
      --record "$dir/record.json" --out "$jsonl" "$@"; then
    echo "bench_peer: measuring $engine failed"; failed=$((failed + 1))
  fi
}

# 1. The exact cases, every engine, every step.
tiny_flag=(); [ "$tiny" = 1 ] && tiny_flag=(--tiny)
"$yardstick" scenes "$work/cases" --dts "$dts" "${tiny_flag[@]}" >"$work/cases.txt"
while read -r name dt dur toml; do
  bodies=${toml%.toml}.json
  "$rigidsim" export "$toml" --to "$bodies"
  for engine in $case_engines; do
    wanted "$engine" || continue
    dir=$work/runs/$name@$dt/$engine
    if run "$engine" "$toml" "$bodies" "$dur" 1 0.0166667 "$reps" "$dir" </dev/null; then
      measure "$engine" "$dir" "$bodies" --case "$name" --dt "$dt"
    else
      echo "bench_peer: $engine on $name (dt $dt) failed"; failed=$((failed + 1))
    fi
  done
done <"$work/cases.txt"

# 2. Pours: scripts/stress.sh's `crowd` scenes (the bundled nuts and bolts,
# scatter box widened), every engine for the same simulated span.
source scripts/crowd.sh
pour() { # count: its crowd, for the same simulated span in every engine
  crowd_of "$1" | sed -e "s/^until_rest = true/until_rest = false\nduration = $pour_time/"
}
for count in ${counts//,/ }; do
  toml=$work/pour$count.toml
  pour "$count" >"$toml"
  bodies=$work/pour$count.json
  "$rigidsim" export "$toml" --to "$bodies"
  for engine in $pour_engines; do
    wanted "$engine" || continue
    dur=$pour_time
    for c in "${caps[@]}"; do [ "${c%%=*}" = "$engine@$count" ] && dur=${c#*=}; done
    dir=$work/runs/pour$count/$engine
    every=10; [ "$tiny" = 1 ] && every=1
    if run "$engine" "$toml" "$bodies" "$dur" "$every" 0.1 "$pour_reps" "$dir" </dev/null; then
      measure "$engine" "$dir" "$bodies" --pour "$count"
    else
      echo "bench_peer: $engine on the $count-body pour failed"; failed=$((failed + 1))
    fi
  done
done

commit=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
"$yardstick" report "$jsonl" --out "$out" --commit "$commit" \
  --command "scripts/bench_peer.sh --reps $reps --pour-reps $pour_reps --dts $dts --counts $counts --pour-time $pour_time${caps[*]:+ --cap ${caps[*]}}"
echo "bench_peer: done in $(( $(date +%s) - started )) s, $failed failed; results in $out"
[ "$failed" -eq 0 ]
