#!/usr/bin/env bash
# Sourced by the scripts that pour the thesis scene's nuts and bolts onto
# the 2 m floor (stress.sh's `crowd` scenes, the pour benchmarks, the CI
# lab runs). Run from the repository root.
#
# crowd COUNT HALF_WIDTH TOP: scenes/nuts_and_bolts.toml with COUNT bodies
#   scattered in ±HALF_WIDTH m up to TOP m, run to rest within 60 s, without
#   its [render] section, on standard output.
# crowd_of COUNT: the pours of the benchmarks: 200 (±0.35 m, up to 1.0 m,
#   `crowd200`), 1000 (±0.55 m, up to 1.6 m, `crowd1000`), and any other
#   count in 50's box (±0.3 m, up to 0.6 m).
crowd() {
  sed -e "s/^count = 20/count = $1/" -e "s/^min = .*/min = [-$2, -$2, 0.1]/" \
      -e "s/^max = .*/max = [$2, $2, $3]/" -e "s/^max_duration = .*/max_duration = 60.0/" \
      -e '/^\[render\]/,$d' scenes/nuts_and_bolts.toml
}
crowd_of() {
  case $1 in
    200) crowd 200 0.35 1.0 ;;
    1000) crowd 1000 0.55 1.6 ;;
    *) crowd "$1" 0.3 0.6 ;;
  esac
}

# zero_g_crowd SIDE: SIDE³ nuts and bolts, no gravity and no floor, on a
# lattice 7 cm apart, each flying towards the centre at 0.4 m/s (±0.1 in
# each axis) and turning at up to 3 rad/s, all from seed 1; restitution 1
# and friction 0, so momentum and energy have exact answers (their drift,
# scripts/drift.py). Runs 1 s. Its islands seldom hold 8 moving bodies, so
# `pile_bodies = 2` lets the contact model's dial act on every approach
# between moving bodies (at dial 0 it changes nothing). On standard output.
zero_g_crowd() {
  python3 - "$1" <<'PY'
import math, random, sys
side = int(sys.argv[1])
rng = random.Random(1)
print("# Zero-g crowd: momentum and energy are exact (scripts/crowd.sh).")
print("[world]\ngravity = [0.0, 0.0, 0.0]\ndt = 0.01\nduration = 1.0\npile_bodies = 2\n")
print('[objects.nut]\nshape = { nut = { across_flats = 0.04, thickness = 0.016, '
      'hole_radius = 0.011, sides = 32 } }\ndensity = 7850.0\nrestitution = 1.0\nfriction = 0.0\n')
print('[objects.bolt]\nshape = { bolt = { head_across_flats = 0.03, head_height = 0.012, '
      'shaft_radius = 0.009, shaft_length = 0.04, sides = 40 } }\ndensity = 7850.0\n'
      'restitution = 1.0\nfriction = 0.0\n')
half = (side - 1) / 2
for i in range(side):
    for j in range(side):
        for k in range(side):
            p = [0.07 * (c - half) for c in (i, j, k)]
            r = math.sqrt(sum(x * x for x in p)) or 1.0
            v = [-0.4 * x / r + rng.uniform(-0.1, 0.1) for x in p]
            w = [rng.uniform(-3.0, 3.0) for _ in range(3)]
            q = [rng.gauss(0, 1) for _ in range(4)]
            n = math.sqrt(sum(x * x for x in q))
            fmt = lambda xs: "[" + ", ".join(f"{x:.6f}" for x in xs) + "]"
            print(f'[[bodies]]\nobject = "{"nut" if (i + j + k) % 2 else "bolt"}"')
            print(f"position = {fmt(p)}\norientation = {fmt([x / n for x in q])}")
            print(f"velocity = {fmt(v)}\nangular_velocity = {fmt(w)}\n")
PY
}
