#!/usr/bin/env bash
# The thesis's network experiment (SPEC 4, figs. 5.3–5.5), over a lab in a
# box (scripts/lab.sh): the bundled nuts-and-bolts pour with 20 and 50
# bodies and crowd200 (200 bodies, the pour of scripts/stress.sh), on 1 PC
# (one rank, no lab) and on 2, 3 and 4 PCs linked at 100 Mbit/s and at
# 10 Mbit/s, one rank a PC, no render rank, in one sitting. Then
# bench/tools turns the summaries into network.csv, network.md and
# network.png under bench/results/<machine>/ (BENCH_MACHINE, default
# <host>-<cores>cpu).
#
# Runs are capped by --duration (the thesis ran to rest): NB_DURATION
# seconds simulated for the 20 and 50 bodies (default 5; they end earlier
# if all bodies rest), POUR_DURATION for crowd200 (default 1.5).
#
# Usage: scripts/bench_network.sh [--tiny]      (or TINY=1)
# Knobs: HOSTS="2 3 4" LINKS="100mbit 10mbit" REPS=1 RUN_LIMIT=300
# Needs what scripts/lab.sh needs (root, network namespaces); without it
# the script says why and exits 1.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
source scripts/crowd.sh

tiny=${TINY:-0}
[ "${1:-}" = "--tiny" ] && tiny=1
machine=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
if [ "$tiny" = 1 ]; then
  out=${OUT:-target/bench-tiny/$machine}
  HOSTS="2"; LINKS="10mbit"; REPS=1; COUNTS="20"; NB_DURATION=0.05; POUR_DURATION=""
else
  out=${OUT:-bench/results/$machine}
  HOSTS=${HOSTS:-"2 3 4"}
  LINKS=${LINKS:-"100mbit 10mbit"}
  REPS=${REPS:-1}
  COUNTS="20 50"
  NB_DURATION=${NB_DURATION:-5}
  POUR_DURATION=${POUR_DURATION:-1.5}
fi
RUN_LIMIT=${RUN_LIMIT:-300}
if ! why=$(bash scripts/lab.sh --check 2>&1); then
  echo "bench_network: no lab can be made here: $why" >&2
  exit 1
fi

cargo build --release --quiet
(cd bench/tools && cargo build --release --quiet --target-dir ../../"${CARGO_TARGET_DIR:-target}")
bin="${CARGO_TARGET_DIR:-target}"/release/rigidsim
mkdir -p "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
started=$(date +%s)

scene() { # bodies: the bundled pour with that many bodies, no render section
  local f="$tmp/nb$1.toml"
  if [ "$1" = 200 ]; then
    crowd_of 200 >"$f"
  else
    sed -e "s/^count = 20/count = $1/" -e '/^\[render\]/,$d' scenes/nuts_and_bolts.toml >"$f"
  fi
  echo "$f"
}
manifest="$tmp/manifest.csv"
echo "series,bodies,ranks,variant,rep,dir" >"$manifest"
run() { # bodies, hosts, link (1pc: one rank without a lab), rep
  local bodies=$1 hosts=$2 link=$3 rep=$4
  local dir="$tmp/runs/n${bodies}_h${hosts}_${link}_r$rep" duration=$NB_DURATION
  [ "$bodies" = 200 ] && duration=$POUR_DURATION
  local opts=(--no-render --no-progress --sample-every 0.5 --out "$dir")
  [ -z "$duration" ] || opts+=(--duration "$duration")
  echo "bench_network: $bodies bodies, $hosts PC(s), $link, rep $rep" >&2
  if [ "$link" = 1pc ]; then
    timeout "$RUN_LIMIT" mpirun -np 1 "$bin" "$(scene "$bodies")" "${opts[@]}" >"$tmp/log" 2>&1 || true
  else
    timeout "$RUN_LIMIT" bash scripts/lab.sh --name rsbench --hosts "$hosts" --link "$link" \
      "$(scene "$bodies")" "${opts[@]}" >"$tmp/log" 2>&1 || { tail -5 "$tmp/log" >&2; true; }
  fi
  echo "network,$bodies,$hosts,$link,$rep,$dir" >>"$manifest"
}
scenes="$COUNTS"
[ -z "$POUR_DURATION" ] || scenes="$scenes 200"
for rep in $(seq 1 "$REPS"); do
  for bodies in $scenes; do
    run "$bodies" 1 1pc "$rep"
    for link in $LINKS; do
      for hosts in $HOSTS; do
        run "$bodies" "$hosts" "$link" "$rep"
      done
    done
  done
done

"${CARGO_TARGET_DIR:-target}"/release/rigidsim-bench-report "$manifest" "$out"
{
  echo "machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) cores"
  echo "mpirun: $(mpirun --version 2>/dev/null | head -1)"
  echo "rigidsim: $(git describe --always --dirty 2>/dev/null || echo unknown)"
  echo "settings: HOSTS='$HOSTS' LINKS='$LINKS' REPS=$REPS NB_DURATION=$NB_DURATION POUR_DURATION=$POUR_DURATION tiny=$tiny"
  echo "load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "elapsed: $(( $(date +%s) - started )) s"
} >"$out/network_machine.txt"
cat "$out/network_machine.txt"
echo "bench_network: results in $out"
