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
"$(dirname "$0")/apt-install-missing.sh" install-deps "${packages[@]}"
