#!/usr/bin/env bash
# The test command (after deploy/build.sh): every GoogleTest suite under ctest (the MPI ones
# under a real mpirun, the preview's in a real headless Chromium), then each libFuzzer target
# for 60 s (clang, ASan + UBSan; deploy/fuzz.sh). FUZZ_SECONDS=0 skips the fuzzing.
set -euo pipefail
cd "$(dirname "$0")/.."
ctest --test-dir build --output-on-failure -j2
if [ "${FUZZ_SECONDS:-60}" != 0 ]; then deploy/fuzz.sh "${FUZZ_SECONDS:-60}"; fi
