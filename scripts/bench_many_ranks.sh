#!/usr/bin/env bash
# The pours on many ranks: `crowd200` for 2 s and `crowd1000` for its first
# 1.5 s (scripts/crowd.sh's scenes), and with `bin` in SCENES the 300 parts
# dropped into a bin (scenes/bin_of_parts.toml) for its first second,
# --no-render, under `mpirun -np R` for each R in RANKS (RANKSBIN for the
# bin), REPS runs each (REPS1000 for the 1000-body pour, one of the bin),
# all interleaved. Rank counts above the machine's cores are left out (never
# oversubscribed: this measures what cores give). Writes
# OUT/runs/<scene>-<R>-<rep>/summary.json and OUT/manifest.csv, then with the
# report tool (bench/tools) OUT/many_ranks.{md,csv,png}: per scene the speed-up
# over one rank beside Amdahl's bound from the one-rank runs' parallel
# fraction, the efficiency, rank 0's waiting, and a check that every run of a
# scene ends on one state hash.
#
# Usage: scripts/bench_many_ranks.sh                  build, run, report
#        BIN=path/to/rigidsim REPORT=0 OUT=dir scripts/bench_many_ranks.sh
#                                  runs only (a machine without the toolchain)
#        scripts/bench_many_ranks.sh --report DIR     the report of DIR's runs
#        scripts/bench_many_ranks.sh --tiny           1 and 2 ranks, a few steps,
#                                  into target/bench-tiny/ (CI: it cannot rot)
# Knobs: RANKS="1 2 4 8 16" RANKSBIN=RANKS SCENES="200 1000" (add bin) REPS=3
#        REPS1000=1 DURATION200=2 DURATION1000=1.5 DURATIONBIN=1.0
#        RUN_LIMIT=600 (seconds a run may take) DEADLINE (seconds after
#        which no run starts; none by default)
#        SPLIT=1: each run also with --split-groups (its own table, scene
#        crowdN-split)
#        PREDICT=1: the one-rank runs predict the others (`--predict`) over
#        the link a short 2-rank run measures first (`message_latency_s`,
#        the worker's `link_bytes_per_s`); the report puts the prediction
#        beside the measure
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$(pwd)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

report() {
  local dir=$1
  cargo build --release --quiet --manifest-path bench/tools/Cargo.toml \
    --target-dir "${CARGO_TARGET_DIR:-target}"
  local tool
  tool=$(cd "${CARGO_TARGET_DIR:-target}" && pwd)/release/rigidsim-bench-report
  # The manifest's run folders are relative to DIR.
  (cd "$dir" && "$tool" manifest.csv .)
  cat "$dir/many_ranks.md"
}

if [ "${1:-}" = "--report" ]; then
  report "${2:?usage: scripts/bench_many_ranks.sh --report DIR}"
  exit 0
fi

machine=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
out=${OUT:-bench/results/$machine/many_ranks}
if [ "${1:-}" = "--tiny" ] || [ "${TINY:-0}" = 1 ]; then
  out=${OUT:-target/bench-tiny/$machine/many_ranks}
  RANKS="1 2"; RANKSBIN="1 2"; REPS=1; REPS1000=1; DURATION200=0.05
  DURATION1000=0.02; DURATIONBIN=0.02
fi
RANKS=${RANKS:-"1 2 4 8 16"}; SCENES=${SCENES:-"200 1000"}
REPS=${REPS:-3}; REPS1000=${REPS1000:-1}
DURATION200=${DURATION200:-2}; DURATION1000=${DURATION1000:-1.5}
DURATIONBIN=${DURATIONBIN:-1.0}; RANKSBIN=${RANKSBIN:-$RANKS}
RUN_LIMIT=${RUN_LIMIT:-600}; DEADLINE=${DEADLINE:-0}

if [ -z "${BIN:-}" ]; then
  source scripts/setup.sh
  cargo build --release --quiet
  BIN=${CARGO_TARGET_DIR:-target}/release/rigidsim
fi
mkdir -p "$out/runs"
out=$(cd "$out" && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# A private copy: a rebuild during the runs must not mix versions.
cp "$BIN" "$tmp/rigidsim"

cores=$(nproc)
# The rank counts of RANKS (or of RANKSBIN for the bin) this machine has
# cores for.
ranks_of() {
  local list=$RANKS
  [ "$1" = bin ] && list=$RANKSBIN
  for r in $list; do
    if [ "$r" -le "$cores" ]; then echo "$r"; else
      echo "bench_many_ranks: $r ranks left out ($cores cores here)" >&2; fi
  done
}

# The link a 2-rank run measures (one way, and the worker's bytes per
# second), which the one-rank runs predict over.
predict_args=()
if [ "${PREDICT:-0}" = 1 ] && [ "$cores" -ge 2 ]; then
  source scripts/crowd.sh
  crowd_of 50 >"$tmp/probe.toml"
  mpirun -np 2 "$tmp/rigidsim" "$tmp/probe.toml" --duration 0.05 --no-render \
    --no-progress --out "$tmp/probe" >/dev/null 2>&1
  number() { grep -o "\"$1\": *[0-9.e+-]*" "$tmp/probe/summary.json" | tail -1 | sed 's/.*: *//'; }
  latency=$(number message_latency_s); rate=$(number link_bytes_per_s)
  # `message_latency_s` is a round trip.
  latency_us=$(awk -v s="$latency" 'BEGIN { printf "%.3f", s * 1e6 / 2 }')
  echo "bench_many_ranks: predicting over the link measured: $latency_us µs one way, $rate B/s"
  predict_args=(--predict --link-latency-us "$latency_us" --link-bytes-per-s "$rate")
fi

# Each run as by default (on several ranks a pile is split where that
# measures faster), and with SPLIT=1 also with every group split
# (`--split-groups`).
variants=("")
if [ "${SPLIT:-0}" = 1 ]; then variants+=("-split"); fi
source scripts/crowd.sh
manifest=$out/manifest.csv
echo "series,bodies,ranks,variant,rep,dir" >"$manifest"
max_reps=$REPS
[ "$REPS1000" -gt "$max_reps" ] && max_reps=$REPS1000
# Each scene's file, name and bodies (the bin's, from its one object).
for n in $SCENES; do
  if [ "$n" = bin ]; then cp scenes/bin_of_parts.toml "$tmp/bin.toml"; else
    crowd_of "$n" >"$tmp/crowd$n.toml"; fi
done
scene_name() { if [ "$1" = bin ]; then echo bin; else echo "crowd$1"; fi; }
started=$(date +%s)
for rep in $(seq 1 "$max_reps"); do
  for n in $SCENES; do
    reps=$REPS; duration=$DURATION200
    if [ "$n" = 1000 ]; then reps=$REPS1000; duration=$DURATION1000; fi
    if [ "$n" = bin ]; then reps=1; duration=$DURATIONBIN; fi
    [ "$rep" -le "$reps" ] || continue
    scene=$(scene_name "$n")
    for r in $(ranks_of "$n"); do
      for split in "${variants[@]}"; do
        elapsed=$(( $(date +%s) - started ))
        if [ "$DEADLINE" -gt 0 ] && [ "$elapsed" -ge "$DEADLINE" ]; then
          echo "bench_many_ranks: past DEADLINE ($DEADLINE s): $scene$split on $r ranks not run"
          continue
        fi
        name=$scene$split-$r-$rep
        echo "bench_many_ranks: $scene$split, $r rank(s), rep $rep ($elapsed s so far)"
        rm -rf "${out:?}/runs/$name"
        extra=()
        [ "$r" = 1 ] && extra=("${predict_args[@]}")
        timeout "$RUN_LIMIT" mpirun -np "$r" "$tmp/rigidsim" "$tmp/$scene.toml" \
          --duration "$duration" --no-render --no-progress --sample-every 0.5 \
          ${split:+--split-groups} ${extra[@]+"${extra[@]}"} --out "$out/runs/$name" >/dev/null 2>&1 ||
          echo "bench_many_ranks: run failed or cut off ($scene$split, $r ranks)"
        # Only the summary is kept (the trajectories are megabytes).
        find "$out/runs/$name" -type f ! -name summary.json -delete 2>/dev/null || true
        bodies=$n
        [ "$n" = bin ] && bodies=300
        echo "many_ranks,$bodies,$r,$scene$split,$rep,runs/$name" >>"$manifest"
      done
    done
  done
done
echo "bench_many_ranks: runs done in $(( $(date +%s) - started )) s; results in $out"
if [ "${REPORT:-1}" = 1 ]; then report "$out"; fi
