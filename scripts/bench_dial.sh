#!/usr/bin/env bash
# The contact model's dial (`world.speculative_speed`, `--speculative-speed`)
# on the pours of scripts/bench_pour.sh, the bin of parts and a zero-g
# crowd, one rank, --no-render: for each setting, run time against error
# (deepest overlap, the LCP's worst violation, energy at the end, when the
# run came to rest, the pushes of speculative contacts and those that left
# their pair apart: ghosts, the impact events that repaired a solved pair's
# overlap; on the zero-g crowd, whose momentum and energy are exact, their
# drift, scripts/drift.py) and what the step did (impact events by approach
# speed, contact rows). One sitting, settings interleaved per scene; a table
# on standard output and in bench/results/<machine>/dial.md (BENCH_MACHINE,
# default <host>-<cores>cpu).
#
# Usage: scripts/bench_dial.sh [--tiny]        (or TINY=1)
# Knobs: DIALS="0 0.049 1.0" (m/s) POURS="200 1000 bin zero-g"
#        BIG_DURATION=1.5 (crowd1000) ZERO_G_SIDE=6 (6³ bodies)
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

tiny=${TINY:-0}
[ "${1:-}" = "--tiny" ] && tiny=1
machine=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
DIALS=${DIALS:-"0 0.049 1.0"}
BIG_DURATION=${BIG_DURATION:-1.5}
if [ "$tiny" = 1 ]; then
  POURS="20 zero-g"; ZERO_G_SIDE=2; out=${OUT:-target/bench-tiny/$machine}; opts=(--duration 0.2)
else
  POURS=${POURS:-"200 1000 bin zero-g"}; out=${OUT:-bench/results/$machine}; opts=()
fi

cargo build --release --quiet
bin="${CARGO_TARGET_DIR:-target}"/release/rigidsim
mkdir -p "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
source scripts/crowd.sh
rows=()
# scene_of POUR FILE: the scene a pour name stands for, written to FILE.
scene_of() {
  case $1 in
    bin) cp scenes/bin_of_parts.toml "$2" ;;
    zero-g) zero_g_crowd "${ZERO_G_SIDE:-6}" >"$2" ;;
    *) crowd_of "$1" >"$2" ;;
  esac
}
for pour in $POURS; do
  scene=$tmp/$pour.toml
  scene_of "$pour" "$scene"
  run_opts=("${opts[@]}")
  case $pour in
    1000) run_opts=(--duration "$BIG_DURATION") ;;
    zero-g) run_opts=(); "$bin" export "$scene" --to "$tmp/zero-g.json" ;;
  esac
  for dial in $DIALS; do
    dir=$tmp/run-$pour-$dial
    echo "bench_dial: $pour, speculative speed $dial m/s" >&2
    "$bin" "$scene" --speculative-speed "$dial" --no-render --no-progress \
      --sample-every 0.5 "${run_opts[@]}" --out "$dir" >/dev/null 2>&1 ||
      echo "bench_dial: run failed ($pour, $dial)" >&2
    drift=-
    if [ "$pour" = zero-g ] && [ -f "$dir/trajectory.csv" ]; then
      drift=$(python3 scripts/drift.py "$tmp/zero-g.json" "$dir/trajectory.csv" | tr ' ' ,)
    fi
    rows+=("$pour $dial $dir $drift")
  done
done
cat >"$tmp/table.py" <<'PY'
import json, sys
print("| scene | dial (m/s) | simulated s | wall s | wall per simulated s | worst 0.1 s frame | ended "
      "| events (< g·dt/2, < 0.2, < 1, faster m/s) | of them repairs | contacts | LCP rows "
      "| deepest overlap (µm) | worst LCP violation (m/s) | energy at end (J) "
      "| speculative pushes (ghosts) | drift of momentum, angular momentum, energy |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for line in sys.stdin:
    count, dial, d, drift = line.split()
    try:
        s = json.load(open(d + "/summary.json"))
    except OSError:
        print(f"| {count} | {dial} | failed |")
        continue
    c = s["counters"]
    solve = c["solve"]
    bands = ", ".join(map(str, c["toi_events_by_approach"]))
    cells = [count, dial, f"{s['sim_time_s']:.2f}", f"{s['wall_time_s']:.2f}",
             f"{s['wall_time_s'] / max(s['sim_time_s'], 1e-9):.3f}", f"{s['worst_frame_s']:.3f}",
             s["end_reason"], f"{c['toi_events']} ({bands})", str(c.get("overlap_repairs", "—")),
             str(c["contacts"]), str(solve["rows"]),
             f"{s['max_penetration_m'] * 1e6:.2f}", f"{solve.get('worst_violation', 0.0):.1e}",
             f"{s['energy_final_j']:.3f}",
             f"{c.get('speculative_pushes', '—')} ({c.get('speculative_ghosts', '—')})",
             drift.replace(",", ", ")]
    print("| " + " | ".join(cells) + " |")
PY
printf '%s\n' "${rows[@]}" | python3 "$tmp/table.py" | tee "$out/dial.md"
echo "bench_dial: results in $out/dial.md" >&2
