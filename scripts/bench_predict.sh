#!/usr/bin/env bash
# The speed-up a one-rank run predicts (`--predict`, summary.json's
# distributed.predicted, docs/architecture.md "The speed-up a lab can
# expect") against what the ranks measure, on this machine, --no-render:
#   - shared memory: a short 2-rank run measures the link (round trip and
#     rate to the worker); one rank then predicts over that link, and
#     `mpirun -np 2` measures the ratio it predicts against one rank run
#     without --predict (whose measuring is not the run's);
#   - the lab's default link (100 Mbit/s as scripts/lab.sh measured it):
#     one rank predicts 2, 4, 8 and 16 ranks, with its groups whole and
#     with --split-groups (the parts it steps are the tasks predicted);
#   - with LAB=1, scripts/lab.sh with 2 PCs at 100 and 10 Mbit/s measures
#     crowd200 against one rank's prediction over each link.
# Scenes: crowd200 for 2 s (REPS runs each, interleaved), crowd1000 for
# 1.5 s and the bin of parts for BIN_DURATION s (one run each).
# Prints and writes bench/results/<machine>/predict.md.
#
# Usage: scripts/bench_predict.sh
#        scripts/bench_predict.sh --tiny   crowd200 and the bin for a few steps,
#                                  into target/bench-tiny/ (CI: it cannot rot)
# Knobs: REPS=3 BIN_DURATION=1.0 SCENES="crowd200 crowd1000 bin" (SCENES= for
# the lab runs alone) LAB=0
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
source scripts/crowd.sh

machine=${BENCH_MACHINE:-$(hostname)-$(nproc)cpu}
out=${OUT:-bench/results/$machine}
REPS=${REPS:-3}; BIN_DURATION=${BIN_DURATION:-1.0}
SCENES=${SCENES-"crowd200 crowd1000 bin"}; LAB=${LAB:-0}
tiny=0
if [ "${1:-}" = "--tiny" ] || [ "${TINY:-0}" = 1 ]; then
  tiny=1; out=${OUT:-target/bench-tiny/$machine}; REPS=1; SCENES="crowd200 bin"
  BIN_DURATION=0.02; LAB=0
fi
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

cargo build --release --quiet
mkdir -p "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
bin=$tmp/rigidsim
cp "${CARGO_TARGET_DIR:-target}"/release/rigidsim "$bin"
commit=$(git rev-parse --short HEAD)
[ -n "$(git status --porcelain --untracked-files=no)" ] && commit="$commit+"

crowd_of 200 >"$tmp/crowd200.toml"
crowd_of 1000 >"$tmp/crowd1000.toml"
cp scenes/bin_of_parts.toml "$tmp/bin.toml"
duration() {
  if [ "$tiny" = 1 ]; then echo 0.03; return; fi
  case $1 in crowd200) echo 2 ;; crowd1000) echo 1.5 ;; bin) echo "$BIN_DURATION" ;; esac
}
reps() { [ "$1" = crowd200 ] && echo "$REPS" || echo 1; }
run() { # run NAME NP OUTDIR [options]
  local scene=$1 np=$2 dir=$3; shift 3
  echo "bench_predict: $scene, $np rank(s) $*" >&2
  mpirun -np "$np" "$bin" "$tmp/$scene.toml" --duration "$(duration "$scene")" \
    --no-render --no-progress --out "$dir" "$@" >/dev/null 2>&1 ||
    echo "bench_predict: run failed ($scene, $np ranks)" >&2
}

# The shared-memory link, as a 2-rank run measures it.
mpirun -np 2 "$bin" "$tmp/crowd200.toml" --duration 0.1 --no-render --no-progress \
  --out "$tmp/probe" >/dev/null 2>&1
read -r latency_us rate < <(python3 - "$tmp/probe/summary.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
rate = next(r["link_bytes_per_s"] for r in s["per_rank"] if r.get("link_bytes_per_s"))
print(s["distributed"]["message_latency_s"] / 2 * 1e6, rate)
PY
)
echo "bench_predict: shared memory: $latency_us us one way, $rate B/s" >&2

for scene in $SCENES; do
  for rep in $(seq 1 "$(reps "$scene")"); do
    run "$scene" 1 "$tmp/$scene-one-$rep"
    run "$scene" 1 "$tmp/$scene-shm-$rep" --predict --link-latency-us "$latency_us" --link-bytes-per-s "$rate"
    run "$scene" 2 "$tmp/$scene-np2-$rep"
  done
  run "$scene" 1 "$tmp/$scene-lab" --predict
  run "$scene" 1 "$tmp/$scene-split-lab" --predict --split-groups
done
if [ "$LAB" = 1 ]; then
  for link in 100mbit 10mbit; do
    RIGIDSIM_BIN=$bin bash scripts/lab.sh --hosts 2 --link "$link" "$tmp/crowd200.toml" \
      --duration 2 --no-render --no-progress --out "$tmp/lab-$link" >/dev/null 2>&1 ||
      echo "bench_predict: lab run failed ($link)" >&2
    # One rank predicts over the link the lab run measured.
    read -r l r < <(python3 - "$tmp/lab-$link/summary.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
rate = next(r["link_bytes_per_s"] for r in s["per_rank"] if r.get("link_bytes_per_s"))
print(s["distributed"]["message_latency_s"] / 2 * 1e6, rate)
PY
)
    run crowd200 1 "$tmp/lab-$link-predicted" --predict --link-latency-us "$l" --link-bytes-per-s "$r"
  done
fi

python3 - "$tmp" "$commit" "$REPS" "$LAB" "$latency_us" "$rate" $SCENES >"$out/predict.md" <<'PY'
import json, os, statistics, sys
tmp, commit, reps, lab, latency_us, rate = sys.argv[1:7]
scenes = sys.argv[7:]
load = lambda d: json.load(open(f"{tmp}/{d}/summary.json"))
print(f"## Predicted against measured, at {commit} (`scripts/bench_predict.sh`)\n")
if not scenes:
    print("(no scenes: SCENES=)\n")
print(f"Shared memory as a 2-rank run measured it: {float(latency_us):.2f} µs one way, "
      f"{float(rate) / 1e6:.0f} MB/s.\n")
print("| scene | runs | 1 rank [s] | 2 ranks [s] | measured 2 / 1 | predicted 2 / 1 | prediction off by | 1 rank with --predict [s] | state hashes |")
print("|---|---|---|---|---|---|---|---|---|")
for scene in scenes:
    n = reps if scene == "crowd200" else "1"
    plain = [load(f"{scene}-one-{r}") for r in range(1, int(n) + 1)]
    one = [load(f"{scene}-shm-{r}") for r in range(1, int(n) + 1)]
    two = [load(f"{scene}-np2-{r}") for r in range(1, int(n) + 1)]
    w1 = statistics.median(s["wall_time_s"] for s in plain)
    w2 = statistics.median(s["wall_time_s"] for s in two)
    wp = statistics.median(s["wall_time_s"] for s in one)
    pred = statistics.median(1 / s["distributed"]["predicted"][0]["speedup"] for s in one)
    hashes = {s["state_hash"] for s in plain + one + two}
    print(f"| {scene} | {n} | {w1:.2f} | {w2:.2f} | {w2 / w1:.3f} | {pred:.3f} | "
          f"{(pred - w2 / w1) / (w2 / w1) * 100:+.0f} % | {wp:.2f} | {', '.join(sorted(hashes))} |")
print("\n## What the predicted wall is made of, over shared memory (`by_stage`)\n")
print("Seconds of the one-rank run's prediction: rank 0's own (everything outside "
      "the stages other ranks take) and each stage as the scheduler would share it.\n")
print("| scene | ranks | predicted [s] | rank 0's own | island solves | group steps | first stage of split groups | narrowphase |")
print("|---|---|---|---|---|---|---|---|")
for scene in scenes:
    for p in load(f"{scene}-shm-1")["distributed"]["predicted"]:
        b = p.get("by_stage")
        if b is None or p["ranks"] not in (2, 16):
            continue
        print(f"| {scene} | {p['ranks']} | {p['wall_s']:.3f} | {b['coordinator_s']:.3f} | "
              f"{b['island_solves_s']:.3f} | {b['group_steps_s']:.3f} | {b['prepare_pairs_s']:.3f} | "
              f"{b['narrowphase_s']:.3f} |")
print("\n## Predicted over a lab's 100 Mbit/s (the default link)\n")
print("| scene | groups | 1 rank [s] | 2 ranks | 4 | 8 | 16 | largest group's share | group-stage bound at 16 | the same, events shared | state hash |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for scene in scenes:
    for groups, run in (("whole", f"{scene}-lab"), ("split", f"{scene}-split-lab")):
        s = load(run)
        d = s["distributed"]
        sp = " | ".join(f"{p['speedup']:.2f}" for p in d["predicted"])
        shared = d.get("event_shared_bound") or [{"speedup": float("nan")}]
        print(f"| {scene} | {groups} | {s['wall_time_s']:.2f} | {sp} | {d['largest_group_share']:.3f} | "
              f"{d['group_speedup_bound'][-1]['speedup']:.2f} | {shared[-1]['speedup']:.2f} | "
              f"{s['state_hash']} |")
if lab == "1":
    print("\n## crowd200 on 2 PCs of scripts/lab.sh against one rank's prediction over the measured link\n")
    print("| link | measured round trip [ms] | measured rate [MB/s] | 2 PCs [s] | 1 rank [s] | measured 2 / 1 | predicted 2 / 1 |")
    print("|---|---|---|---|---|---|---|")
    for link in ("100mbit", "10mbit"):
        if not os.path.exists(f"{tmp}/lab-{link}/summary.json"):
            print(f"| {link} | – | – | run failed | | | |")
            continue
        two, one = load(f"lab-{link}"), load(f"lab-{link}-predicted")
        rate = next(r["link_bytes_per_s"] for r in two["per_rank"] if r.get("link_bytes_per_s"))
        print(f"| {link} | {two['distributed']['message_latency_s'] * 1e3:.2f} | {rate / 1e6:.2f} | "
              f"{two['wall_time_s']:.2f} | {one['wall_time_s']:.2f} | "
              f"{two['wall_time_s'] / one['wall_time_s']:.3f} | "
              f"{1 / one['distributed']['predicted'][0]['speedup']:.3f} |")
PY
cat "$out/predict.md"
