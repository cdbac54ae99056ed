#!/bin/bash
# Issue 5 figure (a), repeated: Whitted at 1 spp, priority and scanline order alternated,
# three pairs at 480x270 and at 960x540; areas under RMSE(t) per pair (tools/bench/RESULTS.md).
#   flock /tmp/raystack-bench.lock tools/bench/priority_repeat_bench.sh WORK_DIR STORE
# RAYSTACK_BUILD: the build folder to measure (default: build).
set -e
cd "$(dirname "$0")/../.."; root=$PWD; w=${1:-$(mktemp -d)}; store=${2:?usage: priority_repeat_bench.sh WORK_DIR STORE (a store of --generate spheres:200000)}
mkdir -p "$w"
rs=$(realpath "${RAYSTACK_BUILD:-build}")/master/raystack; plot=$root/tools/plot/raystack-plot
. tools/bench/bench_scene.sh
scene() { local name=$1; shift; bench_scene "$w/$name.json" "$store" "$@"; }
for size in "480 270" "960 540"; do
  set -- $size; tag=${1}x$2
  scene ref-$tag $1 $2 whitted 64 99; scene w-$tag $1 $2 whitted 1 1
  [ -f $w/ref-$tag.exr ] || $rs render $w/ref-$tag.json --threads 2 --no-png -q --output $w/ref-$tag.exr
  for run in 1 2 3; do
    for order in priority scanline; do
      $rs render $w/w-$tag.json --threads 2 --no-png -q --output $w/o.exr --reference $w/ref-$tag.exr \
        --convergence-log $w/$tag-$order-$run.csv --log-interval 0.01 --pixel-order $order
    done
    echo "== $tag run $run (load $(cut -d' ' -f1 /proc/loadavg))"
    $plot "priority=$w/$tag-priority-$run.csv" "scanline=$w/$tag-scanline-$run.csv" --area --metric rmse -o $w/unused.png 2>&1 | tail -4
  done
done
