#!/usr/bin/env bash
# Builds the .deb from ./build, installs it on this machine (apt-get, so its dependencies come
# along), and renders the built-in default scene with the installed programs (raystack-demo,
# under mpirun). CI runs it after the tests; it needs root or sudo.
set -euo pipefail
cd "$(dirname "$0")/.."
sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi
(cd build && cpack -G DEB > /dev/null)
deb="$(ls -t build/raystack_*.deb | head -n1)"
echo "check-package: installing $deb"
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --reinstall "./$deb" > /dev/null
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
(cd "$work" && /usr/bin/raystack-demo demo)
test -s "$work/demo/default.exr"
test -s /usr/share/doc/raystack/SCENE_FORMAT.md  # where --help sends the reader
test -x /usr/bin/raystack-plot
test -x /usr/share/raystack/slurm/raystack.sbatch  # a cluster installed from the .deb has it
/usr/bin/raystack render --help | grep -q /usr/share/doc/raystack/  # where the documents are
echo "check-package: the installed raystack rendered $(du -h "$work/demo/default.exr" | cut -f1) of EXR"
