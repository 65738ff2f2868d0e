#!/usr/bin/env bash
# The thesis's experiments (issue 7 §2, SPEC 2.8 and 4), under mpirun:
#   1. load profile: the 27-sphere scene, 5000 frames at 0.01 s, one rank;
#   2. scaling: nuts and bolts onto the 2 m floor, to rest, for each body
#      count in COUNTS (plus BIG_COUNTS, and HUGE_COUNTS on one rank only) and
#      each rank count in RANKS; at 5 ranks the last rank renders (4 compute
#      ranks + render, like the thesis's 4 PCs + SGI), below 5 every rank
#      computes; at 10 Hz (dt = 0.01 s, the thesis) and at 60 Hz (dt = frame
#      = 1/60 s);
#   3. heterogeneous ranks: 3 ranks with worker 2 slowed 3x (--slow-rank);
#   4. real cores: bench/scenes/eight_stacks.toml (--no-sleep, no render) and
#      the 200-body pour for 2 s (no render), on
#      1 rank and on as many ranks as there are cores (CORE_RANKS), never
#      oversubscribed: what distributing gains.
# Then bench/tools turns the summaries into CSV, Markdown and PNG under
# bench/results/<machine>/ (BENCH_MACHINE, default <host>-<cores>cpu).
#
# Usage: scripts/bench_scaling.sh [--tiny]      (or TINY=1)
# Knobs: COUNTS="1 2 5 ..." BIG_COUNTS="100" HUGE_COUNTS="200" RANKS="1 2 3 4 5"
#        REPS=3 REPS60=1 LP_REPS=5 CORE_REPS=5 RUN_LIMIT=300 (seconds a run may take)
#        KEEP_RUNS=1 keeps every run's folder (summary.json, trajectory).
# On a machine with more cores, run it there with its own BENCH_MACHINE and
# keep both result folders.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

tiny=${TINY:-0}
[ "${1:-}" = "--tiny" ] && tiny=1
machine=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
if [ "$tiny" = 1 ]; then
  out=${OUT:-target/bench-tiny/$machine}
  COUNTS="1 2"; BIG_COUNTS=""; HUGE_COUNTS=""; RANKS="1 2"
  REPS=1; REPS60=1; LP_REPS=1; HETERO_COUNTS="2"
  extra=(--duration 0.05); lp_extra=(--duration 0.05)
else
  out=${OUT:-bench/results/$machine}
  COUNTS=${COUNTS:-"1 2 5 10 15 20 25 30 40 50"}
  BIG_COUNTS=${BIG_COUNTS:-"100"}
  HUGE_COUNTS=${HUGE_COUNTS:-"200"}
  RANKS=${RANKS:-"1 2 3 4 5"}
  REPS=${REPS:-3}; REPS60=${REPS60:-1}; LP_REPS=${LP_REPS:-5}
  HETERO_COUNTS=${HETERO_COUNTS:-"20 50"}
  extra=(); lp_extra=()
fi
RUN_LIMIT=${RUN_LIMIT:-300}
# Runs of each real-cores configuration (medians of 5 by default).
CORE_REPS=${CORE_REPS:-$([ "$tiny" = 1 ] && echo 1 || echo 5)}

cargo build --release --quiet
cargo build --release --quiet --manifest-path bench/tools/Cargo.toml --target-dir "${CARGO_TARGET_DIR:-target}"
mkdir -p "$out"
tmp=$(mktemp -d)
if [ "${KEEP_RUNS:-0}" = 1 ]; then echo "bench_scaling: runs kept in $tmp"; else trap 'rm -rf "$tmp"' EXIT; fi
# A private copy: a rebuild of target/ during the runs must not mix versions.
cp "${CARGO_TARGET_DIR:-target}"/release/rigidsim "$tmp/rigidsim"
bin=$tmp/rigidsim
manifest=$tmp/manifest.csv
echo "series,bodies,ranks,variant,rep,dir" >"$manifest"
started=$(date +%s)

# run SERIES BODIES RANKS VARIANT REP SCENE [rigidsim options...]
run() {
  local series=$1 bodies=$2 ranks=$3 variant=$4 rep=$5 scene=$6
  shift 6
  local dir=$tmp/$series/$bodies-$ranks-$variant-$rep
  echo "$series,$bodies,$ranks,$variant,$rep,$dir" >>"$manifest"
  if ! timeout "$RUN_LIMIT" mpirun -np "$ranks" --oversubscribe "$bin" "$scene" --no-progress \
      --sample-every 0.1 --out "$dir" "$@" "${extra[@]}" >"$tmp/last.log" 2>&1; then
    echo "bench_scaling: $series bodies=$bodies ranks=$ranks $variant failed or passed ${RUN_LIMIT}s:" >&2
    tail -3 "$tmp/last.log" >&2 || true
  fi
}

# scene BODIES HZ -> path of a nuts-and-bolts scene with that many bodies.
scene() {
  local n=$1 hz=$2 f=$tmp/scenes/nb_${1}_${2}.toml
  mkdir -p "$tmp/scenes"
  if [ ! -f "$f" ]; then
    if [ "$hz" = 60 ]; then
      sed -e "s/^count = 20/count = $n/" -e "s/^dt = 0.01/dt = 0.016666666666666666/" \
          -e "s/^frame_interval = 0.1 /frame_interval = 0.016666666666666666 /" scenes/nuts_and_bolts.toml >"$f"
    else
      sed -e "s/^count = 20/count = $n/" scenes/nuts_and_bolts.toml >"$f"
    fi
    grep -q "^count = $n\$" "$f" || { echo "bench_scaling: could not set count in $f" >&2; exit 1; }
  fi
  echo "$f"
}

# Ranks beyond 4 include the render rank (the scene's [render] section).
render_opt() { if [ "$1" -ge 5 ]; then echo ""; else echo "--no-render"; fi; }
variant_of() { if [ "$1" -ge 5 ]; then echo "render"; else echo "compute"; fi; }

# Warm-up (page cache, CPU frequency), not recorded.
mpirun -np 1 "$bin" "$(scene 10 10)" --no-render --no-progress --out "$tmp/warmup" "${extra[@]}" >/dev/null 2>&1 || true

echo "bench_scaling: load profile (${LP_REPS} runs)"
for rep in $(seq 1 "$LP_REPS"); do
  dir=$tmp/load_profile/$rep
  echo "load_profile,27,1,compute,$rep,$dir" >>"$manifest"
  mpirun -np 1 "$bin" scenes/load_profile.toml --no-render --no-progress --sample-every 1 \
    --out "$dir" "${lp_extra[@]}" >/dev/null 2>&1 || echo "bench_scaling: load profile run $rep failed" >&2
done

for hz in 10 60; do
  reps=$REPS; [ "$hz" = 60 ] && reps=$REPS60
  echo "bench_scaling: scaling at $hz Hz ($reps run(s) a point)"
  for rep in $(seq 1 "$reps"); do
    for n in $COUNTS $BIG_COUNTS; do
      for r in $RANKS; do
        # shellcheck disable=SC2046
        run "rt$hz" "$n" "$r" "$(variant_of "$r")" "$rep" "$(scene "$n" "$hz")" $(render_opt "$r")
      done
    done
  done
  if [ "$hz" = 10 ]; then
    for n in $HUGE_COUNTS; do run rt10 "$n" 1 compute 1 "$(scene "$n" 10)" --no-render; done
  fi
done

echo "bench_scaling: heterogeneous ranks"
for rep in $(seq 1 "$REPS"); do
  for n in $HETERO_COUNTS; do
    run hetero "$n" 3 even "$rep" "$(scene "$n" 10)" --no-render
    run hetero "$n" 3 slow "$rep" "$(scene "$n" 10)" --no-render --slow-rank 2=3.0
    run hetero "$n" 3 even_force "$rep" "$(scene "$n" 10)" --no-render --force-distribute
    run hetero "$n" 3 slow_force "$rep" "$(scene "$n" 10)" --no-render --force-distribute --slow-rank 2=3.0
  done
done

echo "bench_scaling: real cores"
CORE_RANKS=${CORE_RANKS:-$(nproc)}
# The 200-body pour of scripts/stress.sh (crowd200), 2 s: its group steps
# are the distributed work (POUR_DURATION seconds).
pour_opts=(--duration "${POUR_DURATION:-2.0}")
[ "$tiny" = 1 ] && pour_opts=()   # extra already holds --tiny's duration
source scripts/crowd.sh
crowd_of 200 >"$tmp/crowd200.toml"
for rep in $(seq 1 "$CORE_REPS"); do
  for r in $(printf '%s\n' 1 "$CORE_RANKS" | sort -un); do
    run cores 121 "$r" compute "$rep" bench/scenes/eight_stacks.toml --no-render --no-sleep
    run cores_pour 201 "$r" compute "$rep" "$tmp/crowd200.toml" --no-render "${pour_opts[@]}"
  done
done

"${CARGO_TARGET_DIR:-target}"/release/rigidsim-bench-report "$manifest" "$out"
{
  echo "machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) cores"
  echo "mpirun: $(mpirun --version 2>/dev/null | head -1)"
  echo "rigidsim: $(git describe --always --dirty 2>/dev/null || echo unknown)"
  echo "settings: COUNTS='$COUNTS' BIG_COUNTS='$BIG_COUNTS' HUGE_COUNTS='$HUGE_COUNTS' RANKS='$RANKS' REPS=$REPS REPS60=$REPS60 LP_REPS=$LP_REPS CORE_REPS=$CORE_REPS tiny=$tiny"
  echo "elapsed: $(( $(date +%s) - started )) s"
} >"$out/scaling_machine.txt"
cat "$out/scaling_machine.txt"
echo "bench_scaling: results in $out"
