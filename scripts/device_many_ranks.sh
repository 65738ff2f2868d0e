#!/usr/bin/env bash
# The many-ranks series (`scripts/bench_many_ranks.sh`) on a many-core
# machine that has no Open MPI and fetches nothing, such as the one the
# `device` tool lends: Debian's Open MPI packages and a stripped build
# travel in `.ompi/` (ignored by git), and are unpacked there into
# `.ompi/root`, never into `/`.
#
# Usage: scripts/device_many_ranks.sh pack   here: downloads the packages and
#                                            strips a release build into .ompi/
#        scripts/device_many_ranks.sh run    there (.ompi carried): unpacks,
#                                            runs the series into $OUT/many_ranks
#        scripts/device_many_ranks.sh check  here: `run` on 1 and 2 ranks for a
#                                            few steps with the unpacked Open MPI
#                                            alone (no system Open MPI library
#                                            may be opened)
#        scripts/bench_many_ranks.sh --report DIR   here, on what came back
# The series is sized for one call under ten minutes on 16 cores (knobs as
# bench_many_ranks.sh's): crowd200 for 2 s and crowd1000 for 1.5 s on 1, 2,
# 4, 8 and 16 ranks, the bin for 1.0 s on 1 and 16 (a pile's run takes
# about as long on any count: 40 s and 110 s on one core of the 2-core
# machine), one run each; no run starts after DEADLINE (400) seconds or
# runs longer than RUN_LIMIT (180). The one-rank runs predict the others
# (`--predict`) over the link a 2-rank run measures first.
set -euo pipefail
cd "$(dirname "$0")/.."
here=$(pwd)
pack_dir=$here/.ompi
# Open MPI 4.1's programs and libraries, and the libraries they and their
# components open that a bare Debian-like system may lack.
packages=(openmpi-bin openmpi-common libopenmpi3 libpmix2 libevent-core-2.1-7
  libevent-pthreads-2.1-7 libhwloc15 libfabric1 libibverbs1 ibverbs-providers
  librdmacm1 libucx0 libpsm2-2 libpsm-infinipath1 libnl-3-200
  libnl-route-3-200 libnuma1 libmunge2 libudev1 libuuid1 libatomic1)

pack() {
  # Only what travels: the packages and the build (about 21 MB).
  rm -rf "$pack_dir/debs" "$pack_dir/root" "$pack_dir/bin"
  mkdir -p "$pack_dir/debs"
  (cd "$pack_dir/debs" && apt-get download "${packages[@]}" >/dev/null)
  cargo build --release --quiet
  cp "${CARGO_TARGET_DIR:-target}/release/rigidsim" "$pack_dir/rigidsim"
  strip "$pack_dir/rigidsim"
  echo "device_many_ranks: packed $(du -sh "$pack_dir" | cut -f1) into .ompi/" \
    "(carry .ompi; the device's whole carry is 64 MiB)"
}

# Unpacks the packages into .ompi/root and points PATH, the loader and
# Open MPI at it.
unpack() {
  local root=$pack_dir/root
  if [ ! -x "$root/usr/bin/orterun" ]; then
    mkdir -p "$root"
    for f in "$pack_dir"/debs/*.deb; do dpkg -x "$f" "$root"; done
  fi
  # `mpirun` is an alternatives link to the system's; orterun is the program.
  mkdir -p "$pack_dir/bin"
  ln -sf "$root/usr/bin/orterun" "$pack_dir/bin/mpirun"
  local lib=$root/usr/lib/x86_64-linux-gnu
  export PATH=$pack_dir/bin:$root/usr/bin:$PATH
  export LD_LIBRARY_PATH=$lib/openmpi/lib:$lib:$root/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  export OPAL_PREFIX=$root/usr
  export OPAL_LIBDIR=$lib/openmpi/lib
  export PMIX_INSTALL_PREFIX=$root/usr
  # Components and help files are found under the prefix; the system's
  # configuration (if any) is not read.
  export OMPI_MCA_mca_base_param_files=/dev/null
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
}

series() {
  unpack
  local out=${OUT:?set OUT, the folder whose files come back}/many_ranks
  BIN=$pack_dir/rigidsim REPORT=0 OUT=$out \
    RANKS=${RANKS:-"1 2 4 8 16"} RANKSBIN=${RANKSBIN:-"1 16"} \
    SCENES=${SCENES:-"200 1000 bin"} REPS=${REPS:-1} \
    DURATION1000=${DURATION1000:-1.5} DURATIONBIN=${DURATIONBIN:-1.0} \
    DEADLINE=${DEADLINE:-400} RUN_LIMIT=${RUN_LIMIT:-180} PREDICT=1 scripts/bench_many_ranks.sh
}

case "${1:-}" in
  pack) pack ;;
  run) series ;;
  check)
    [ -x "$pack_dir/rigidsim" ] || pack
    rm -rf "$pack_dir/root"
    unpack
    log=$(mktemp)
    # Every Open MPI file the runs open must come from .ompi/root.
    LD_DEBUG=libs LD_DEBUG_OUTPUT=$log.ld OUT=${OUT:-$(mktemp -d)} RANKS="1 2" \
      RANKSBIN="1" SCENES="200 bin" DURATION200=0.05 DURATION1000=0.02 \
      DURATIONBIN=0.02 series
    if cat "$log".ld.* | grep -E 'calling init: /usr/lib/x86_64-linux-gnu/(openmpi|libmpi|libopen-|libpmix|libhwloc|libevent|libucx|libuc[pstm]|libfabric)'; then
      echo "device_many_ranks: the system's Open MPI was opened (above)" >&2
      exit 1
    fi
    opened=$(cat "$log".ld.* | grep -c "calling init: $pack_dir/root" || true)
    rm -f "$log" "$log".ld.*
    if [ "${opened:-0}" -eq 0 ]; then
      echo "device_many_ranks: no library was opened from .ompi/root" >&2
      exit 1
    fi
    # What was unpacked does not travel (`pack` leaves it out too).
    rm -rf "$pack_dir/root" "$pack_dir/bin"
    echo "device_many_ranks: check passed ($opened libraries opened from .ompi/root)"
    ;;
  *)
    echo "usage: scripts/device_many_ranks.sh pack|run|check" >&2
    exit 2
    ;;
esac
