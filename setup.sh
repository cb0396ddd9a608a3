#!/usr/bin/env bash
# Installs the Debian 12 packages this project builds with, if any is missing (uses sudo when not
# root). Everything else (Eigen, CHOLMOD, Catch2, OpenMP via g++, nlohmann-json) comes from them.
set -euo pipefail
packages=(g++ cmake make libeigen3-dev libsuitesparse-dev catch2 nlohmann-json3-dev)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup.sh: installing ${missing[*]}" >&2
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y --no-install-recommends "${missing[@]}"
fi
