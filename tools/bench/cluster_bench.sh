#!/usr/bin/env bash
# Distribution figures for tools/bench/RESULTS.md (issue 4): an emulated cluster on this
# machine. N = 1, 2, 4, 8 slaves under mpirun, each capped to a CPU share (cgroup v1
# cpu.cfs_quota_us, QUOTA percent of a core, through cpu_capped.sh), one ray thread each, a
# block cache smaller than the model; two frames of the same view (first, then warm); block
# modes loc and rem (loc also with LATENCY_US injected per read). Prints a Markdown table, with
# the master's utilisation (slaves' busy ray-thread time over N x frame time) and, for rem, the
# requests to owners, the loader's runs they carried, and a request's mean round trip, where the
# slaves' ray threads waited (for tiles, for blocks, for their first tile), and the
# slaves' CPU time (whole processes, and their ray and loader threads) against N = 1's. SLAVES
# (default "1 2 4 8") picks the cluster sizes; rem skips 1. REPEATS (default 3) runs the whole
# set that many times, interleaved, so a noisy moment hits every configuration alike: frame
# seconds are medians over the repeats, the other columns come from the run with the median
# first frame. Each efficiency is the median of the repeats' own efficiencies, each against
# the T_1 of the same repeat (run minutes apart at most): this VM's speed drifts by up to
# +-15% over a bench, and a T_1 from one moment against a T_N from another carries that drift
# into the efficiency.
#
#   tools/bench/cluster_bench.sh [SCENE] [CACHE_MB] [QUOTA] [LATENCY_US]
#   RAYSTACK_BUILD: the build folder whose raystack runs (default: build)
set -euo pipefail
cd "$(dirname "$0")/../.."
scene=${1:-tools/bench/scenes/default2.json}
cache_mb=${2:-24}
quota=${3:-20}
latency=${4:-1000}
slave_counts=${SLAVES:-1 2 4 8}
repeats=${REPEATS:-3}
store=$(tools/bench/scene_store.py "$scene")
if [ ! -f "$store/index.bin" ]; then
  echo "cluster_bench: no block store at $store (the scene's \"store\")." >&2
  echo "  The default scene's store comes from deploy/run-default.sh, or alone:" >&2
  echo "  build/tools/prep/raystack-prep --generate spheres:2000000 -o build/default-store --mem-limit 512" >&2
  exit 2
fi
work=$(mktemp -d)
mkdir -p build/bench  # the scene's output folder
trap 'rm -rf "$work"; rmdir /sys/fs/cgroup/cpu/raystack_bench_r* 2>/dev/null || true' EXIT
run() {  # slaves blocks latency repeat -> prints the stats file
  local n=$1 blocks=$2 lat=$3 out="$work/s-$1-$2-$3-$4.json"
  RAYSTACK_CPU_QUOTA_PCT=$quota mpirun --allow-run-as-root --oversubscribe -np $((n + 1)) \
      -x RAYSTACK_CPU_QUOTA_PCT tools/bench/cpu_capped.sh \
      "${RAYSTACK_BUILD:-build}"/master/raystack render "$scene" --threads 1 --cache-mb "$cache_mb" \
      --blocks "$blocks" --io-latency-us "$lat" --no-png -q --stats "$out" > /dev/null
  echo "$out"
}
# One untimed run first: the first run after other work reads the store back into the page
# cache (it was 25% slower than the next ones), which would inflate the first repeat's T_1.
run 1 loc 0 warmup > /dev/null
results=()
for r in $(seq 1 "$repeats"); do
  for blocks_lat in "loc 0" "loc $latency" "rem 0"; do
    set -- $blocks_lat
    for n in $slave_counts; do
      if [ "$1" = rem ] && [ "$n" = 1 ]; then continue; fi  # one slave cannot hold the model
      results+=("$1 $2 $n $r $(run "$n" "$1" "$2" "$r")")
    done
  done
done
python3 - "$quota" "$cache_mb" "${results[@]}" <<'PY'
import json, statistics, sys
quota, cache = sys.argv[1], sys.argv[2]
rows = [r.split() for r in sys.argv[3:]]
by_config = {}  # per configuration: each repeat's frames, by repeat
for blocks, lat, n, r, path in rows:
    by_config.setdefault((blocks, lat, int(n)), {})[r] = json.load(open(path))
def efficiency(blocks, lat, n, f):
    """Median over the repeats of T_1 / (N T_N), each repeat against its own T_1."""
    base = by_config.get(("loc", lat, 1)) or by_config.get(("loc", "0", 1)) or {}
    per_round = [base[r][f]["seconds"] / (n * frames[f]["seconds"])
                 for r, frames in by_config[(blocks, lat, n)].items() if r in base]
    return (statistics.median(per_round), per_round) if per_round else (None, [])
data = {}  # per configuration: the run with the median first frame, seconds the medians
for key, by_repeat in by_config.items():
    all_runs = list(by_repeat.values())
    by_first = sorted(all_runs, key=lambda frames: frames[0]["seconds"])
    chosen = [dict(fr) for fr in by_first[len(by_first) // 2]]
    for f, fr in enumerate(chosen):
        fr["seconds"] = statistics.median(frames[f]["seconds"] for frames in all_runs)
        fr["all_seconds"] = [frames[f]["seconds"] for frames in all_runs]
    data[key] = chosen
repeats = max(len(v) for v in by_config.values())
print(f"each slave: {quota}% of a core, 1 ray thread, {cache} MB block cache; seconds on the master's clock, "
      f"medians of {repeats} interleaved runs (each run's seconds in brackets)")
print()
print("| blocks | latency us | slaves | frame | seconds | efficiency T1/(N TN), per repeat | utilisation | ray threads' waits per slave, s: tiles / blocks / first tile | imbalance | MB over the network | pixel stream share | blocks MB from disk or peers | MB between peers | peer requests / runs (mean wait ms) | slaves' CPU s: process (ray, loader) | CPU / N=1's |")
print("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for (blocks, lat, n), frames in sorted(data.items(), key=lambda kv: (kv[0][0], int(kv[0][1]), kv[0][2])):
    base = data.get(("loc", lat, 1)) or data.get(("loc", "0", 1))
    for f, fr in enumerate(frames):
        eff_median, eff_rounds = efficiency(blocks, lat, n, f)
        eff = (f"{eff_median:.2f} ({', '.join(f'{e:.2f}' for e in eff_rounds)})"
               if eff_median is not None else "-")
        fetches = sum(s["fetches"] for s in fr["slaves"])
        wait = sum(s["fetch_wait_seconds"] for s in fr["slaves"])
        runs = sum(s.get("fetch_runs", s["fetches"]) for s in fr["slaves"])
        fetch_text = f"{fetches} / {runs} ({wait / fetches * 1e3:.1f})" if fetches else "-"
        to_master = sum(s["bytes_to_master"] + s["bytes_from_master"] for s in fr["slaves"])
        pixel = sum(s["pixel_bytes"] for s in fr["slaves"])
        peers = sum(s["bytes_from_peers"] for s in fr["slaves"])
        blocks_mb = sum(s["bytes_read"] for s in fr["slaves"]) / 1e6
        net = (to_master + peers) / 1e6
        every = ", ".join(f"{x:.2f}" for x in fr["all_seconds"])
        cpu = lambda frame, key: sum(s.get(key, 0) for s in frame["slaves"])
        cpu_text = (f"{cpu(fr, 'process_cpu_seconds'):.2f} ({cpu(fr, 'ray_cpu_seconds'):.2f}, "
                    f"{cpu(fr, 'loader_cpu_seconds'):.2f})")
        base_cpu = cpu(base[f], "process_cpu_seconds") if base else 0
        cpu_ratio = f"{cpu(fr, 'process_cpu_seconds') / base_cpu:.2f}" if base_cpu else "-"
        # The wait for the first tile (the master finishing the frame before) is outside the
        # frame's seconds; the tile waits shown are those after it.
        first = [max(0.0, s.get("engine_seconds", 0) - s["seconds"]) for s in fr["slaves"]]
        tiles_wait = [max(0.0, s.get("ray_tile_wait_seconds", 0) - s["threads"] * w)
                      for s, w in zip(fr["slaves"], first)]
        mean = lambda xs: sum(xs) / max(1, len(xs))
        blocks_wait = mean([s.get("ray_idle_seconds", 0) for s in fr["slaves"]])
        waits = f"{mean(tiles_wait):.2f} / {blocks_wait:.2f} / {mean(first):.2f}"
        print(f"| {blocks} | {lat} | {n} | {'first' if f == 0 else 'warm'} | {fr['seconds']:.2f} ({every}) | {eff} | "
              f"{fr['utilisation']:.2f} | {waits} | {fr['imbalance']*100:.1f}% | {net:.1f} | {pixel/1e6/max(net,1e-9)*100:.0f}% | "
              f"{blocks_mb:.1f} | {peers/1e6:.1f} | {fetch_text} | {cpu_text} | {cpu_ratio} |")
PY
