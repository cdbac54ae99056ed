#!/usr/bin/env bash
# Figures of "Error against run time" for tools/bench/RESULTS.md (issue 5): convergence logs of
# a few renders against high-spp references, the plots (tools/bench/plots/) and the areas.
#
#   tools/bench/error_time_bench.sh [WORK_DIR]      (run it under flock /tmp/raystack-bench.lock)
#
# RAYSTACK_BUILD: the build folder to measure (default: build); PLOTS_DIR: where the plots go
# (default: tools/bench/plots, the published ones, overwritten).
#
# (a) priority vs scanline, in core: a Whitted scene at 1 spp (the order alone: the error is
#     mostly pixels not yet computed), and a path-traced scene at 32 spp (passes 1, 1, 2, 4,
#     ...), priority order (first pass in priority-matrix rounds) against scanline order with
#     the same passes and against scanline with every sample of a tile at once (--pass-spp =
#     spp, the classic tile renderer); areas under RMSE(t) up to the end of the shortest run.
# (b) the variance-based estimate against the RMSE to a 512-spp reference (another seed, so
#     its noise is independent) over time, from the priority run.
# (c) stack vs sync on an out-of-core scene: the default scene's 2 M triangles (59 MB of
#     decoded blocks) with a 16 MB block cache, Whitted with 8 jittered samples per pixel,
#     against a 64-spp reference rendered in core; block reads as they come (page cache) and
#     with 1 ms added to each (--io-latency-us 1000, a network filesystem); and stack in
#     scanline order, with passes and with every sample of a tile at once, for the block loads
#     the priority rounds and the passes cost.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$PWD
work=${1:-$(mktemp -d)}
build=$(realpath "${RAYSTACK_BUILD:-build}")
plots=$(realpath -m "${PLOTS_DIR:-tools/bench/plots}")
mkdir -p "$work" "$plots"
raystack=$build/master/raystack
plot=$root/tools/plot/raystack-plot
prep=$build/tools/prep/raystack-prep
threads=2

[ -d "$work/small-store" ] || "$prep" --generate spheres:200000 -o "$work/small-store" -q
[ -d "$work/default-store" ] || "$prep" --generate spheres:2000000 -o "$work/default-store" --mem-limit 512 -q

. tools/bench/bench_scene.sh
scene() {  # name store width height integrator spp seed
  local name=$1
  shift
  bench_scene "$work/$name.json" "$@"
}

render() {  # scene log extra...
  local s=$1 log=$2
  shift 2
  "$raystack" render "$work/$s.json" --threads $threads --no-png -q --output "$work/$log.exr" \
      --convergence-log "$work/$log.csv" --log-interval 0.01 "$@"
}

# (a) Whitted, 1 spp: the order alone.
scene whitted-ref small-store 480 270 whitted 64 99
scene whitted small-store 480 270 whitted 1 1
[ -f "$work/whitted-ref.exr" ] || "$raystack" render "$work/whitted-ref.json" --threads $threads \
    --no-png -q --output "$work/whitted-ref.exr"
render whitted a1-priority --reference "$work/whitted-ref.exr" --pixel-order priority
render whitted a1-scanline --reference "$work/whitted-ref.exr" --pixel-order scanline
echo "## (a) Whitted 1 spp: area under RMSE(t)"
"$plot" "priority=$work/a1-priority.csv" "scanline=$work/a1-scanline.csv" --area --metric rmse \
    --title "RMSE against time: priority vs scanline (480x270, Whitted, 1 spp, 2 threads)" \
    -o "$plots"/error_priority_vs_scanline_whitted.png

# (a), (b): small in-core path-traced scene.
scene path-ref small-store 240 135 path 512 99
scene path small-store 240 135 path 32 1
[ -f "$work/path-ref.exr" ] || "$raystack" render "$work/path-ref.json" --threads $threads --no-png -q \
    --output "$work/path-ref.exr"
ref=(--reference "$work/path-ref.exr")
render path a-priority "${ref[@]}" --pixel-order priority
render path a-scanline "${ref[@]}" --pixel-order scanline
render path a-scanline-tiles "${ref[@]}" --pixel-order scanline --pass-spp 32
echo "## (a) area under RMSE(t)"
"$plot" "priority=$work/a-priority.csv" "scanline=$work/a-scanline.csv" \
    "scanline, whole tiles=$work/a-scanline-tiles.csv" --area --metric rmse \
    --title "RMSE against time: priority vs scanline (240x135, path, 32 spp, 2 threads)" \
    -o "$plots"/error_priority_vs_scanline.png
first_full=$(awk -F, '$2=="pass" && $3==1 {print $4; exit}' "$work/a-priority.csv")
echo "## (a) up to the priority run's first full frame ($first_full s)"
"$plot" "priority=$work/a-priority.csv" "scanline=$work/a-scanline.csv" \
    "scanline, whole tiles=$work/a-scanline-tiles.csv" --area --until "$first_full" \
    -o "$work/unused.png"
echo "## (b) error_estimate / rmse at rows where every pixel has >= 4 samples"
awk -F, 'NR > 1 && $8 >= 4 && $9 != "" && $11 != "" {
           printf "%s,%s,%s,%s,%s,%s,%.3f\n", $2, $3, $4, $8, $9, $11, $9 / $11 }' \
    "$work/a-priority.csv" | (echo "event,pass,seconds,min_samples,error_estimate,rmse,ratio"; cat)
"$plot" "priority=$work/a-priority.csv" --estimate --metric rmse \
    --title "Variance-based estimate (dashed) against RMSE to a 512-spp reference" \
    -o "$plots"/error_estimate_vs_rmse.png

# (c): out of core, stack vs sync.
scene ooc-ref default-store 480 270 whitted 64 99
scene ooc default-store 480 270 whitted 8 1
[ -f "$work/ooc-ref.exr" ] || "$raystack" render "$work/ooc-ref.json" --threads $threads --no-png -q \
    --mode incore --output "$work/ooc-ref.exr"
figures() {  # name
  python3 -c "import json,sys; s=json.load(open(sys.argv[1]))[0]; print(sys.argv[2], 'seconds', round(s['seconds'],2), 'rays/s', round(s['rays_per_second']), 'blocks_loaded', s['blocks_loaded'], 'of', s['block_count'], 'cache_peak_MB', round(s['cache_peak_bytes']/2**20,1))" "$work/$1-stats.json" "$1"
}
for latency in 0 1000; do
  for mode in stack sync; do
    render ooc "c-$mode-$latency" --reference "$work/ooc-ref.exr" --mode $mode --cache-mb 16 \
        --io-latency-us $latency --stats "$work/c-$mode-$latency-stats.json"
    figures "c-$mode-$latency"
  done
  echo "## (c) area under RMSE(t), --io-latency-us $latency"
  "$plot" "stack=$work/c-stack-$latency.csv" "sync=$work/c-sync-$latency.csv" --area --metric rmse \
      --title "RMSE against time, out of core (2 M triangles, 16 MB cache, +$latency us/read)" \
      -o "$plots/error_stack_vs_sync_io$latency.png"
done
render ooc c-stack-scanline --reference "$work/ooc-ref.exr" --cache-mb 16 --pixel-order scanline \
    --stats "$work/c-stack-scanline-stats.json"
figures c-stack-scanline
render ooc c-stack-scanline-whole --reference "$work/ooc-ref.exr" --cache-mb 16 \
    --pixel-order scanline --pass-spp 8 --stats "$work/c-stack-scanline-whole-stats.json"
figures c-stack-scanline-whole
for f in a1-priority a1-scanline a-priority a-scanline a-scanline-tiles c-stack-0 c-sync-0 \
         c-stack-1000 c-sync-1000 c-stack-scanline c-stack-scanline-whole; do
  echo "$f: $(tail -1 "$work/$f.csv")"
done
