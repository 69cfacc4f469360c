#!/usr/bin/env bash
# Installs heightcast's build and test dependencies from Debian/Ubuntu packages (only what is missing).
#   bash scripts/deps.sh          what the build and the tests need (gcc)
#   bash scripts/deps.sh clang    that, plus clang and libFuzzer (the sanitizer and fuzz build, scripts/build_sanitized.sh)
set -euo pipefail

# The GL backend and viewer: EGL + GL headers and Mesa's drivers (llvmpipe runs the GL tests headless; the DRI
# drivers must be named, nothing pulls them in), GLFW, glslangValidator (shaders are checked at build time),
# and Xvfb for the viewer's test on machines with no display. ffmpeg makes hc-render's videos of flood scenarios
# (--steps A:B --video OUT.mp4). OpenMPI runs hc-ingest and hc-influence on several processes (mpirun -np N).
# ccache: CI builds the toolkit twice with the same compiler and flags (build/, build-minimal/), and most objects
# of the second come from the cache (scripts/build.sh uses it when installed).
packages=(build-essential cmake pkg-config libgdal-dev gdal-bin libgtest-dev libopenexr-dev libopenvdb-dev
          libboost-iostreams-dev libtbb-dev libblosc-dev
          nlohmann-json3-dev libfmt-dev libglm-dev libproj-dev
          libegl-dev libopengl-dev libgl-dev libegl1 libegl-mesa0 libgl1-mesa-dri libglfw3-dev glslang-tools xvfb xauth ffmpeg
          libopenmpi-dev openmpi-bin ccache)
# clang 14, clang-format and libFuzzer (libclang-rt-14-dev on Debian 12): Debian 12's clang, the one CI builds with.
[ "${1:-}" = clang ] && packages+=(clang clang-format libclang-rt-14-dev)
installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }

missing=()
for p in "${packages[@]}"; do installed "$p" || missing+=("$p"); done
# GeographicLib's package is libgeographiclib-dev since Debian 12 / Ubuntu 23.04, libgeographic-dev before.
installed libgeographiclib-dev || installed libgeographic-dev || missing+=(geographiclib)
[ ${#missing[@]} -eq 0 ] && exit 0

sudo=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "deps.sh: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
  sudo="sudo"
fi
$sudo apt-get update -qq
for i in "${!missing[@]}"; do
  if [ "${missing[$i]}" = geographiclib ]; then
    if apt-cache show libgeographiclib-dev >/dev/null 2>&1; then missing[$i]=libgeographiclib-dev; else missing[$i]=libgeographic-dev; fi
  fi
done
echo "deps.sh: installing ${missing[*]}"
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
