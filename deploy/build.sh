#!/usr/bin/env bash
# Configures and builds raystack in ./build (Release, portable code). Extra arguments go to
# CMake, e.g. deploy/build.sh -DRAYSTACK_NATIVE=ON or -DRAYSTACK_SANITIZE=address,undefined.
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -G Ninja "$@" > /dev/null
cmake --build build
