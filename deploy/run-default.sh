#!/usr/bin/env bash
# The main job on the built-in default scene: generate a 2 M-triangle scene (spheres on a
# floor), convert it into a block store under a 512 MB memory budget, check every block, and
# render it with the ray stack under a 32 MB block cache (the store holds 59 MB of decoded
# blocks, so blocks are loaded, evicted and reloaded while rendering).
# Output: build/default.exr (+ build/default.png); statistics: build/default-stats.json.
set -euo pipefail
cd "$(dirname "$0")/.."
store=build/default-store
build/tools/prep/raystack-prep --generate spheres:2000000 -o "$store" --mem-limit 512
build/tools/info/raystack-info "$store" --verify
build/master/raystack render deploy/default-scene.json --cache-mb 32 --stats build/default-stats.json
