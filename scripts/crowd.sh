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
