#!/usr/bin/env bash
# Installs what rigidsim needs on Debian (once): Open MPI, libclang for rsmpi's
# bindings, Mesa's CPU Vulkan driver for off-screen rendering, ffmpeg for
# video, fontconfig and a font for benchmark plots, for the browser test of
# `rigidsim view`'s replay page: Chromium, Node.js and npm, then the viewer's
# npm packages (viewer/node_modules, from viewer/package-lock.json), and
# iproute2 and openssh-server for the lab in a box, valgrind for the
# instruction counts of scripts/bench_instructions.sh, qemu-user for the
# tests that emulate older CPUs. Safe to run again:
# installs only what is missing.
set -euo pipefail

need=()
command -v mpirun >/dev/null 2>&1 || need+=(openmpi-bin)
dpkg -s libopenmpi-dev >/dev/null 2>&1 || need+=(libopenmpi-dev)
dpkg -s libclang-dev >/dev/null 2>&1 || need+=(libclang-dev)
dpkg -s mesa-vulkan-drivers >/dev/null 2>&1 || need+=(mesa-vulkan-drivers)
command -v ffmpeg >/dev/null 2>&1 || need+=(ffmpeg)
# Benchmark plots (plotters' text rendering links fontconfig and needs a font).
dpkg -s libfontconfig1-dev >/dev/null 2>&1 || need+=(libfontconfig1-dev)
command -v pkg-config >/dev/null 2>&1 || need+=(pkg-config)
dpkg -s fonts-dejavu-core >/dev/null 2>&1 || need+=(fonts-dejavu-core)
# The replay page's browser test (viewer/test/replay_in_chromium.mjs).
command -v chromium >/dev/null 2>&1 || need+=(chromium)
command -v node >/dev/null 2>&1 || need+=(nodejs)
command -v npm >/dev/null 2>&1 || need+=(npm)
# The lab in a box (scripts/lab.sh): namespaces and links (iproute2, with tc),
# unshare (util-linux), an sshd per "PC" and the ssh client mpirun launches with.
command -v ip >/dev/null 2>&1 && command -v tc >/dev/null 2>&1 || need+=(iproute2)
command -v unshare >/dev/null 2>&1 || need+=(util-linux)
[ -x /usr/sbin/sshd ] || need+=(openssh-server)
command -v ssh >/dev/null 2>&1 || need+=(openssh-client)
# Instruction counts for scripts/bench_instructions.sh.
command -v valgrind >/dev/null 2>&1 || need+=(valgrind)
# Older CPUs, emulated, for tests/hosts.rs (results that do not depend on
# the PC's generation).
command -v qemu-x86_64 >/dev/null 2>&1 || need+=(qemu-user)

if [ ${#need[@]} -gt 0 ]; then
  echo "setup: installing ${need[*]}" >&2
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  # openssh-server's package would start a system sshd listening on every
  # address; the lab starts its own, on lab addresses only. Debian's
  # policy-rc.d answer 101 stops the package's service from starting (where
  # no policy is set already).
  policy=""
  if [[ " ${need[*]} " == *" openssh-server "* ]] && [ ! -e /usr/sbin/policy-rc.d ]; then
    policy=/usr/sbin/policy-rc.d
    printf '#!/bin/sh\nexit 101\n' | $sudo tee "$policy" >/dev/null
    $sudo chmod 755 "$policy"
  fi
  rc=0
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null || rc=$?
  [ -z "$policy" ] || $sudo rm -f "$policy"
  [ "$rc" -eq 0 ] || exit "$rc"
fi

# The viewer's packages: playwright-core drives Chromium in the browser test;
# three and esbuild rebuild the committed bundle (viewer/build.mjs). Installed
# again only when the lock file is newer than the last install.
viewer_dir="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/viewer"
if [ ! -f "$viewer_dir/node_modules/.installed" ] || [ "$viewer_dir/package-lock.json" -nt "$viewer_dir/node_modules/.installed" ]; then
  echo "setup: installing the viewer's npm packages (viewer/package-lock.json)" >&2
  (cd "$viewer_dir" && npm ci --no-audit --no-fund --loglevel=error >/dev/null)
  touch "$viewer_dir/node_modules/.installed"
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install Rust (https://rustup.rs) and run again" >&2
  exit 1
fi

# Open MPI refuses to run as root unless told; the CPU Vulkan driver's
# device-select layer prints noise where no desktop runs.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 NODEVICE_SELECT=1
