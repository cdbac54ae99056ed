#!/usr/bin/env bash
# raystack on another CPU: arm64, cross-compiled on an x86-64 Debian 12 machine and run under
# qemu. CI runs it after the tests (it needs root or sudo to install the cross compiler and the
# arm64 libraries; it adds arm64 to dpkg's architectures for good).
#  1. Every source of the programs and libraries in the host build (./build) passes the arm64
#     compiler's syntax and type checks (deploy/cross/syntax_check.py): Debian cannot install
#     arm64 Open MPI or OpenEXR beside the host's, so the renderer itself is checked this far.
#  2. The parts that need neither (RAYSTACK_CORE_ONLY: base, geometry, store, import, prep) are
#     built for arm64 in ./build-arm64 and their tests run under qemu-aarch64: there the ray
#     traversals take their portable code (no SSE), and hits must still equal brute force bit
#     for bit, blocks decode, and PLY and OBJ files read the same.
# Left out under qemu, by name below: a test that starts raystack-info (not in a core build), and
# those that read the kernel's view of the process's memory (qemu-user maps the guest's memory
# itself). The shared real models are left out too (the procedural ones cover the same code;
# under emulation they take minutes each).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "$(dpkg --print-architecture)" != amd64 ]; then
  echo "check-arm64: this cross-checks arm64 from an amd64 machine; this one is $(dpkg --print-architecture)" >&2
  exit 1
fi
sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi

archs="$(dpkg --print-foreign-architectures)"  # captured: grep -q would cut a pipe (pipefail)
if ! grep -qx arm64 <<<"$archs"; then
  echo "check-arm64: adding the arm64 architecture to dpkg"
  $sudo dpkg --add-architecture arm64  # (the installer's apt-get update then reads arm64's lists)
fi
deploy/apt-install-missing.sh check-arm64 g++-aarch64-linux-gnu qemu-user-static \
  liblz4-dev:arm64 libxxhash-dev:arm64 libgtest-dev:arm64

if [ ! -f build/compile_commands.json ]; then deploy/build.sh; fi
deploy/cross/syntax_check.py build/compile_commands.json aarch64-linux-gnu-g++

cmake -S . -B build-arm64 -G Ninja -DCMAKE_TOOLCHAIN_FILE=deploy/cross/aarch64-linux-gnu.cmake \
  -DRAYSTACK_CORE_ONLY=ON -DRAYSTACK_WERROR=ON -DRAYSTACK_SHARED_MODELS="" > /dev/null
cmake --build build-arm64
info_program='OctreeBuilderTest\.InseparableTrianglesKeepFewReferences$'
kernel_memory='HugePageAllocator\.LargeArraysAreAdvisedAsHugePages$|PopulatedArena\.(MemoryIsAskedForOnlyAsPiecesReachIt|ItsMemoryIsAdvisedAsOrdinaryPages)$|PopulatedAllocator\.|PopulateForWrite\.|ReserveForWrite\.'
# (RAYSTACK_SHARED_MODELS in the environment would bring the real models back: unset.)
(cd build-arm64 && env -u RAYSTACK_SHARED_MODELS ctest -j2 --output-on-failure \
   -E "^($info_program|$kernel_memory)")
echo "check-arm64: the core's tests pass on arm64 (under qemu)"
