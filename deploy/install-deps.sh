#!/usr/bin/env bash
# Installs the Debian 12 packages raystack builds and tests with, and nothing else.
#   compiler and build:  build-essential cmake ninja-build pkg-config
#   block store:         liblz4-dev (block compression) libxxhash-dev (block checksums)
#   render job:          libopenmpi-dev openmpi-bin (ranks) libboost-dev (Asio/Beast preview)
#                        libopenexr-dev (image output) libpng-dev (quick-look PNG)
#                        nlohmann-json3-dev (scene files)
#   tests:               libgtest-dev, chromium (the live preview's browser tests, run headless)
#   fuzzing:             clang libclang-rt-14-dev (libFuzzer and sanitizers: deploy/fuzz.sh)
#   plots:               python3-matplotlib (tools/plot/raystack-plot, error against time)
set -euo pipefail
packages=(build-essential cmake ninja-build pkg-config liblz4-dev libxxhash-dev libopenmpi-dev
          openmpi-bin libboost-dev libopenexr-dev libpng-dev nlohmann-json3-dev libgtest-dev
          chromium clang libclang-rt-14-dev python3-matplotlib)
sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi
missing=()
# Installed for this machine's architecture (or for all): a multi-arch package may also be there
# for another one (deploy/check-arm64.sh adds arm64 copies of liblz4-dev and the like), one
# line each.
host="$(dpkg --print-architecture)"
for p in "${packages[@]}"; do
  status="$(dpkg-query -W -f='${Architecture} ${Status}\n' "$p" 2>/dev/null || true)"
  grep -qE "^($host|all) install ok installed$" <<<"$status" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "install-deps: installing ${missing[*]}"
  # (env: sudo would drop DEBIAN_FRONTEND; the lock timeout waits out apt's daily run on a new VM)
  apt=($sudo env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600)
  "${apt[@]}" update -qq
  "${apt[@]}" install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "install-deps: all ${#packages[@]} packages already installed"
fi
