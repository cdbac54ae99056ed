#!/usr/bin/env bash
# The main job on the built-in default scene: generate a 2 M-triangle scene (spheres on a
# floor), convert it into a block store under a 512 MB memory budget, check every block, and
# render it under mpirun on this machine: rank 0 the master, ranks 1-2 two slaves, each with a
# 16 MiB block cache (the store's decoded blocks take 58 MiB and each slave's tiles reach about
# half of them, so blocks are loaded, evicted and reloaded while rendering: the slaves' lines
# say "N blocks loaded (M distinct)", N > M). The image equals a one-process render bit for bit.
# Output: build/default.exr (+ build/default.png); figures per slave: build/default-stats.json.
set -euo pipefail
cd "$(dirname "$0")/.."
store=build/default-store
build/tools/prep/raystack-prep --generate spheres:2000000 -o "$store" --mem-limit 512
build/tools/info/raystack-info "$store" --verify
# --allow-run-as-root: containers and CI run as root; --oversubscribe: 3 ranks on 2 cores;
# --enable-recovery: a slave that dies or stalls costs time, not the job (without it mpirun
# ends every rank when one ends early). With it mpirun's exit code is 0 whatever happened, so
# the image is checked after: raystack-info exits 0 only for a complete frame (a failed job
# left none, or only what it had; the last run's image is removed first).
rm -f build/default.exr build/default.png
mpirun --allow-run-as-root --oversubscribe --enable-recovery -np 3 \
    build/master/raystack render deploy/default-scene.json --threads 1 --cache-mb 16 \
    --stats build/default-stats.json
build/tools/info/raystack-info build/default.exr
