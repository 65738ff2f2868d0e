#!/usr/bin/env bash
# Instructions executed, this checkout's build against BASE's, on fixed
# work: a count that a shared, noisy machine does not change. On the 2-core
# machines this project is measured on, one build's wall time moves by
# ±20 % from run to run, so a change worth 2-5 % cannot be told apart by
# timing; valgrind's instruction count (cachegrind, no cache simulation)
# does not care what else runs (the 200-body pour's 0.3 s: 970 050 799,
# 970 054 913 and 970 077 253 in three runs; a run of a few steps varies
# by about 3e5 instructions, 0.5 % of the 50-body pour's 0.03 s). It is not time: a change that saves
# instructions but misses the cache more can still be slower, and one that
# changes results runs different work. Time stays what the other bench
# scripts measure; this says whether a small change does less work.
#
# The work, each run once per build under valgrind (about 50x slower):
#   islands   the solver benchmark (benches/islands.rs) on ISLANDS, a folder
#             of captured islands (--capture-islands; default the fixtures
#             in tests/data/islands)
#   pour50    the 50-body pour of scripts/crowd.sh, first POUR_DURATION s
#   pour200   the 200-body pour, first POUR_DURATION s
#   pile      the 1000-body pour from CHECKPOINT (a checkpoint of
#             crowd1000 at 1.0 s, each build's own: `rigidsim crowd1000.toml
#             --duration 1.0 --checkpoint-every 1.0 --no-render --out DIR`
#             gives DIR/checkpoint.bin) for PILE_DURATION s; skipped unless
#             CHECKPOINT_<label> names each build's file (labels as printed)
#
# Usage: BASE=commit scripts/bench_instructions.sh   (or --tiny / TINY=1:
#        this checkout only, islands and 0.03 s of the 50-body pour)
# Knobs: ISLANDS=dir POUR_DURATION=0.3 PILE_DURATION=0.02 WORK="islands pour50
#        pour200 pile" OUT=dir (default bench/results/<machine>)
# Writes OUT/instructions_<label>.md: per work, each build's count and the
# ratio here/base, with the state hash of each run (equal hashes: the same
# work done, so the ratio is the saving).
set -euo pipefail
cd "$(dirname "$0")/.."

source scripts/setup.sh

tiny=${TINY:-0}
[ "${1:-}" = "--tiny" ] && tiny=1
machine=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
if [ "$tiny" = 1 ]; then
  # This checkout alone, a few steps: the script cannot rot.
  BASE=none; WORK="islands pour50"; POUR_DURATION=0.03
  out=${OUT:-target/bench-tiny/$machine}
else
  BASE=${BASE:?set BASE to the commit to compare with}
  WORK=${WORK:-"islands pour50 pour200 pile"}
  out=${OUT:-bench/results/$machine}
fi
ISLANDS=${ISLANDS:-tests/data/islands}
POUR_DURATION=${POUR_DURATION:-0.3}
PILE_DURATION=${PILE_DURATION:-0.02}

cargo build --release --quiet
islands_bench() {
  # The islands benchmark's executable, built in the current directory.
  cargo bench --bench islands --no-run 2>&1 |
    grep -o 'target/release/deps/islands-[0-9a-f]*' | head -1
}
mkdir -p "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
source scripts/bench_builds.sh
bench_builds
declare -A isl
here=${labels[-1]}
cp "$(islands_bench)" "$tmp/islands-$here"
isl[$here]=$tmp/islands-$here
if [ ${#labels[@]} -gt 1 ]; then
  base=${labels[0]}
  (cd "target/bench-base/$base" && cp "$(islands_bench)" "$tmp/islands-$base")
  isl[$base]=$tmp/islands-$base
fi

source scripts/crowd.sh
crowd_of 50 >"$tmp/crowd50.toml"
crowd_of 200 >"$tmp/crowd200.toml"
crowd_of 1000 >"$tmp/crowd1000.toml"

# Instructions of one command (valgrind's "I refs").
count() {
  valgrind --tool=cachegrind --cache-sim=no --cachegrind-out-file=/dev/null "$@" \
    2>"$tmp/vg.txt" >/dev/null || { cat "$tmp/vg.txt" >&2; return 1; }
  grep -o 'I *refs: *[0-9,]*' "$tmp/vg.txt" | tr -dc '0-9'
}
hash_of() { grep -o '"state_hash": *"[0-9a-f]*"' "$1/summary.json" | grep -o '[0-9a-f]\{16\}'; }

report=$out/instructions_$here.md
{
  echo "# Instructions executed: ${labels[*]}"
  echo
  echo "\`BASE=$BASE scripts/bench_instructions.sh\` (valgrind cachegrind, no cache"
  echo "simulation); work: $WORK; islands from \`$ISLANDS\`, pours"
  echo "${POUR_DURATION} s, pile ${PILE_DURATION} s from each build's checkpoint."
  echo
  echo "| work | build | instructions | ratio to ${labels[0]} | state hash |"
  echo "|---|---|---|---|---|"
} >"$report"
for work in $WORK; do
  first=""
  for label in "${labels[@]}"; do
    dir=$tmp/run-$work-$label
    case $work in
      islands) n=$(count "${isl[$label]}" "$ISLANDS"); h="-" ;;
      pour50 | pour200)
        n=$(count "${bin[$label]}" "$tmp/crowd${work#pour}.toml" --no-render --no-progress \
          --duration "$POUR_DURATION" --out "$dir")
        h=$(hash_of "$dir") ;;
      pile)
        var=CHECKPOINT_${label//+/_}
        ck=${!var:-}
        if [ -z "$ck" ]; then echo "bench_instructions: pile skipped ($var unset)"; continue 2; fi
        n=$(count "${bin[$label]}" "$tmp/crowd1000.toml" --resume "$ck" --no-render --no-progress \
          --duration "$(awk -v d="$PILE_DURATION" 'BEGIN { print 1.0 + d }')" --out "$dir")
        h=$(hash_of "$dir") ;;
      *) echo "bench_instructions: unknown work $work" >&2; exit 2 ;;
    esac
    [ -z "$first" ] && first=$n
    ratio=$(awk -v a="$n" -v b="$first" 'BEGIN { printf "%.4f", a / b }')
    echo "bench_instructions: $work $label $n ($ratio)"
    echo "| $work | $label | $n | $ratio | $h |" >>"$report"
  done
done
echo "bench_instructions: results in $report"
cat "$report"
