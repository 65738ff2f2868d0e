#!/usr/bin/env bash
# The pour series: the bundled nuts and bolts (scenes/nuts_and_bolts.toml,
# as scripts/stress.sh's `crowd` scenes) poured onto the 2 m floor, one rank,
# --no-render: 50 bodies (±0.3 m, top 0.6 m) and 200 (±0.35 m, top 1.0 m)
# to rest, 1000 (±0.55 m, top 1.6 m) for its first 1.5 s, beside 200 for
# the same 1.5 s (the growth ratio outside solve_islands), and the pile of
# scenes/bin_of_parts.toml (300 bodies in a bin) to rest. Each count runs
# with this checkout's build and with the build of BASE (a commit, default
# be7269b, the last commit before interaction groups), interleaved, in one
# sitting, so the ratios hold on a shared machine. bench/tools turns the
# summaries into pours.md, pours.csv and pours.png under
# bench/results/<machine>/ (BENCH_MACHINE, default <host>-<cores>cpu).
#
# Usage: scripts/bench_pour.sh [--tiny]      (or TINY=1)
# Knobs: BASE=commit (BASE=none: this checkout only) COUNTS="50 200 1000"
#        REPS=3 (50 and 200) REPS_BIG=1 (1000) BIG_DURATION=1.5
#        The 1000-body pour's rep k scatters with seed k (rep 1 is
#        crowd1000 itself): how long its solves take depends on the piles
#        its trajectory builds, so reps of one scene would only repeat one
#        draw (seed 1's first 1.5 s took 38 s, seed 3's 94 s at 52b0fe3).
#        BIN=0 leaves the bin out (the tiny run always does).
#        KEEP_RUNS=1 keeps every run's folder.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

tiny=${TINY:-0}
[ "${1:-}" = "--tiny" ] && tiny=1
machine=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
if [ "$tiny" = 1 ]; then
  out=${OUT:-target/bench-tiny/$machine}
  BASE=${BASE:-none}; COUNTS="5 20"; REPS=1; REPS_BIG=1; extra=(--duration 0.2); BIN=0
else
  out=${OUT:-bench/results/$machine}
  BASE=${BASE:-be7269b}; COUNTS=${COUNTS:-"50 200 1000"}
  REPS=${REPS:-3}; REPS_BIG=${REPS_BIG:-1}; extra=()
fi
BIG_DURATION=${BIG_DURATION:-1.5}

cargo build --release --quiet
cargo build --release --quiet --manifest-path bench/tools/Cargo.toml --target-dir "${CARGO_TARGET_DIR:-target}"
mkdir -p "$out"
tmp=$(mktemp -d)
if [ "${KEEP_RUNS:-0}" = 1 ]; then echo "bench_pour: runs kept in $tmp"; else trap 'rm -rf "$tmp"' EXIT; fi
source scripts/bench_builds.sh
bench_builds

source scripts/crowd.sh
manifest=$tmp/manifest.csv
echo "series,bodies,ranks,variant,rep,dir" >"$manifest"
for count in $COUNTS; do
  crowd_of "$count" >"$tmp/crowd$count.toml"
  reps=$REPS; opts=("${extra[@]}")
  if [ "$count" -ge 1000 ]; then reps=$REPS_BIG; opts=(--duration "$BIG_DURATION"); fi
  for rep in $(seq 1 "$reps"); do
    scene=$tmp/crowd$count.toml
    if [ "$count" -ge 1000 ]; then
      scene=$tmp/crowd$count-seed$rep.toml
      sed "s/^seed = 1\$/seed = $rep/" "$tmp/crowd$count.toml" >"$scene"
    fi
    for label in "${labels[@]}"; do
      dir=$tmp/pour-$count-$label-$rep
      echo "bench_pour: $count bodies, $label, rep $rep"
      "${bin[$label]}" "$scene" --no-render --no-progress \
        --sample-every 0.5 "${opts[@]}" --out "$dir" >/dev/null 2>&1 || echo "bench_pour: run failed ($count, $label)"
      echo "pour,$count,1,$label,$rep,$dir" >>"$manifest"
      if [ "$count" -ge 1000 ]; then
        # 200 bodies over the same window, for the growth ratio.
        [ -f "$tmp/crowd200w.toml" ] || crowd 200 0.35 1.0 >"$tmp/crowd200w.toml"
        "${bin[$label]}" "$tmp/crowd200w.toml" --no-render --no-progress --sample-every 0.5 \
          "${opts[@]}" --out "$dir-window" >/dev/null 2>&1 || echo "bench_pour: run failed (200 window, $label)"
        echo "pour_window,200,1,$label,$rep,$dir-window" >>"$manifest"
      fi
    done
  done
done
if [ "${BIN:-1}" = 1 ]; then
  for label in "${labels[@]}"; do
    dir=$tmp/bin-$label
    echo "bench_pour: the bin, $label"
    "${bin[$label]}" scenes/bin_of_parts.toml --no-render --no-progress \
      --sample-every 0.5 --out "$dir" >/dev/null 2>&1 || echo "bench_pour: run failed (bin, $label)"
    echo "bin,300,1,$label,1,$dir" >>"$manifest"
  done
fi
"${CARGO_TARGET_DIR:-target}"/release/rigidsim-bench-report "$manifest" "$tmp/report" 2>/dev/null
cp "$tmp/report"/pours.* "$out"/
echo "bench_pour: results in $out/pours.md (commits ${labels[*]})"
cat "$out/pours.md"
