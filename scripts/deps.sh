#!/usr/bin/env bash
# Installs heightcast's build and test dependencies from Debian/Ubuntu packages (only what is missing).
set -euo pipefail

packages=(build-essential cmake pkg-config libgdal-dev gdal-bin libgtest-dev)
# GeographicLib's package was renamed in Debian 12 / Ubuntu 23.04 (libgeographic-dev before).
if apt-cache show libgeographiclib-dev >/dev/null 2>&1 || dpkg-query -W libgeographiclib-dev >/dev/null 2>&1; then
  packages+=(libgeographiclib-dev)
else
  packages+=(libgeographic-dev)
fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0

sudo=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "deps.sh: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
  sudo="sudo"
fi
echo "deps.sh: installing ${missing[*]}"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
