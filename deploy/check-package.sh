#!/usr/bin/env bash
# Builds the .deb from ./build, installs it on this machine (apt-get, so its dependencies come
# along), and renders the built-in default scene with the installed programs (raystack-demo,
# under mpirun). CI runs it after the tests; it needs root or sudo.
set -euo pipefail
cd "$(dirname "$0")/.."
sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi
(cd build && cpack -G DEB > /dev/null)
debs=(build/raystack_*.deb)
deb="$(ls -t "${debs[@]}" | sed -n 1p)"  # sed reads to the end: no SIGPIPE under pipefail
echo "check-package: installing $deb"
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --reinstall "./$deb" > /dev/null
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
(cd "$work" && /usr/bin/raystack-demo demo)
test -s "$work/demo/default.exr"
test -s /usr/share/doc/raystack/SCENE_FORMAT.md  # where --help sends the reader
test -x /usr/bin/raystack-plot
test -x /usr/share/raystack/slurm/raystack.sbatch  # a cluster installed from the .deb has it
# The help is captured first: `... | grep -q` stops reading at the first match, and under
# pipefail the writer's SIGPIPE (141) failed CI after a green test run.
help="$(/usr/bin/raystack render --help)"
grep -qF /usr/share/doc/raystack/ <<<"$help"  # where the documents are
echo "check-package: the installed raystack rendered $(du -h "$work/demo/default.exr" | cut -f1) of EXR"
