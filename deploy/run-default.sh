#!/usr/bin/env bash
# The main job on the built-in default scene: generate a 2 M-triangle scene (spheres on a
# floor), convert it into a block store under a 512 MB memory budget, and print what the store
# holds (checking every block). Later versions render it; today the converter is the job.
set -euo pipefail
cd "$(dirname "$0")/.."
store=${1:-build/default-store}
build/tools/prep/raystack-prep --generate spheres:2000000 -o "$store" --mem-limit 512
build/tools/info/raystack-info "$store" --verify
