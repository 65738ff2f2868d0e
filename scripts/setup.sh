#!/usr/bin/env bash
# Installs what rigidsim needs on Debian (once): Open MPI, libclang for rsmpi's
# bindings, Mesa's CPU Vulkan driver for off-screen rendering, ffmpeg for
# video, fontconfig and a font for benchmark plots. Safe to run again: installs only what is missing.
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

if [ ${#need[@]} -gt 0 ]; then
  echo "setup: installing ${need[*]}" >&2
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install Rust (https://rustup.rs) and run again" >&2
  exit 1
fi

# Open MPI refuses to run as root unless told; the CPU Vulkan driver's
# device-select layer prints noise without a desktop session.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 NODEVICE_SELECT=1
