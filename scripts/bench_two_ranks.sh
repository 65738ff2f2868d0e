#!/usr/bin/env bash
# Two ranks against one on the same cores: the 200-body pour (`crowd200`, as
# in scripts/bench_pour.sh) for 2 s, --no-render, `mpirun -np 1` and
# `mpirun -np 2` (one process per core on a 2-core machine), with this
# checkout's build and with BASE's, all four interleaved, REPS runs each.
# Prints and writes bench/results/<machine>/two_ranks.md: medians, the ratio
# of 2 ranks to 1, every run's wall time, how many steps sent their group
# steps to the worker, and a check that each build's runs ended on one state
# hash.
#
# Usage: scripts/bench_two_ranks.sh
# Knobs: BASE=commit (BASE=none: this checkout only) REPS=5 DURATION=2
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

machine=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
out=${OUT:-bench/results/$machine}
BASE=${BASE:-none}; REPS=${REPS:-5}; DURATION=${DURATION:-2}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

cargo build --release --quiet
mkdir -p "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
source scripts/bench_builds.sh
bench_builds

source scripts/crowd.sh
crowd_of 200 >"$tmp/crowd200.toml"
for rep in $(seq 1 "$REPS"); do
  for label in "${labels[@]}"; do
    for np in 1 2; do
      echo "bench_two_ranks: $label, $np rank(s), rep $rep"
      mpirun -np "$np" "${bin[$label]}" "$tmp/crowd200.toml" --duration "$DURATION" \
        --no-render --no-progress --out "$tmp/$label-$np-$rep" >/dev/null 2>&1 ||
        echo "bench_two_ranks: run failed ($label, $np ranks)"
    done
  done
done

python3 - "$tmp" "$REPS" "$DURATION" "${labels[@]}" >"$out/two_ranks.md" <<'PY'
import json, statistics, sys
tmp, reps, duration, labels = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4:]
print(f"## crowd200, {duration} s, --no-render: 2 ranks against 1 ({reps} runs each, interleaved)\n")
print("| commit | ranks | median wall [s] | against 1 rank | runs [s] | steps with group steps sent out |")
print("|---|---|---|---|---|---|")
hashes = {}
for label in labels:
    median = {}
    for np in (1, 2):
        walls, sent = [], []
        for rep in range(1, reps + 1):
            s = json.load(open(f"{tmp}/{label}-{np}-{rep}/summary.json"))
            walls.append(s["wall_time_s"])
            sent.append(str(s["distributed"]["groups_distributed"]) if s.get("distributed") else "—")
            hashes.setdefault(label, set()).add(s["state_hash"])
        median[np] = statistics.median(walls)
        print(f"| {label} | {np} | {median[np]:.3f} | {median[np] / median[1]:.2f} | "
              f"{', '.join(f'{w:.3f}' for w in walls)} | {', '.join(sent)} |")
# Each build's runs on one hash, whatever the rank count (two builds may
# differ: a change can move the trajectory).
print()
for label in labels:
    seen = hashes[label]
    print(f"State hashes of {label}'s runs: {', '.join(sorted(seen))}"
          + (" (one)" if len(seen) == 1 else " (DIFFER)"))
PY
cat "$out/two_ranks.md"
