#!/usr/bin/env bash
# Sourced by the bench scripts that compare this checkout with a base
# commit (bench_pour.sh, bench_two_ranks.sh): private copies of both
# builds in $tmp, so a rebuild of target/ during the runs cannot mix
# versions. BASE's build lives in its own worktree under
# target/bench-base/<commit> and is built once. Needs `tmp` and `BASE` (a
# commit, or none for this checkout only); sets `bin` (label -> binary)
# and `labels` (BASE's first), a label being a short commit, with "+" for a
# checkout with uncommitted changes.
bench_builds() {
  local here base tree
  here=$(git rev-parse --short HEAD 2>/dev/null || echo here)
  [ -n "$(git status --porcelain --untracked-files=no 2>/dev/null)" ] && here="$here+"
  declare -gA bin
  bin[$here]=$tmp/rigidsim-$here
  cp "${CARGO_TARGET_DIR:-target}"/release/rigidsim "${bin[$here]}"
  labels=("$here")
  if [ "$BASE" != none ]; then
    base=$(git rev-parse --short "$BASE")
    tree=target/bench-base/$base
    if [ ! -x "$tree/target/release/rigidsim" ]; then
      rm -rf "$tree"
      git worktree prune
      git worktree add --detach "$tree" "$base" >/dev/null
      (cd "$tree" && cargo build --release --quiet)
    fi
    bin[$base]=$tmp/rigidsim-$base
    cp "$tree/target/release/rigidsim" "${bin[$base]}"
    labels=("$base" "$here")
  fi
}
