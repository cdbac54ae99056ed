#!/usr/bin/env bash
# Out-of-core figures of the ray stack for tools/bench/RESULTS.md (issue 3): one scene rendered
# in the three modes with a cold page cache, side by side, REPEATS times; prints the medians and
# the ratios the issue asks for as a Markdown table, with each mode's CPU time (ray threads,
# loader threads), the floor it puts under T_stack on this machine's cores, and the highest
# T_sync / T_stack those allow.
#
#   tools/bench/ooc_bench.sh SCENE.json CACHE_MB [REPEATS] [-- extra render options]
#
# Cold cache: before every run the store's files are evicted from the page cache
# (posix_fadvise DONTNEED), and each run is capped by a real cgroup-v1 memory group when
# RAYSTACK_MEMCAP_MB is set (stack and sync; through ../shared/tools/memcap.sh), so the page cache cannot keep
# what the block cache dropped.
set -euo pipefail
cd "$(dirname "$0")/../.."
scene=$1 cache_mb=$2 repeats=${3:-3}
shift $(( $# >= 3 ? 3 : $# ))
[ "${1:-}" = "--" ] && shift
extra=("$@")
raystack=${RAYSTACK_BIN:-build/master/raystack}  # RAYSTACK_BIN: another build, for before/after pairs
store=$(tools/bench/scene_store.py "$scene")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

evict() {
  python3 - "$store" <<'PY'
import os, sys
for name in os.listdir(sys.argv[1]):
    fd = os.open(os.path.join(sys.argv[1], name), os.O_RDONLY)
    os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    os.close(fd)
PY
}

run() {  # mode repeat
  local cap=()
  # incore holds the whole store by definition: it runs uncapped.
  if [ -n "${RAYSTACK_MEMCAP_MB:-}" ] && [ "$1" != incore ]; then cap=(../shared/tools/memcap.sh "$RAYSTACK_MEMCAP_MB"); fi
  evict
  "${cap[@]}" "$raystack" render "$scene" --mode "$1" --cache-mb "$cache_mb" -q --no-png \
      --output "$work/out.exr" --stats "$work/$1.$2.json" "${extra[@]}" 2>> "$work/log" ||
    { cat "$work/log" >&2; exit 1; }
}

for r in $(seq 1 "$repeats"); do  # interleaved, so a noisy moment hits every mode alike
  for mode in incore stack sync; do run "$mode" "$r"; done
done
grep memcap "$work/log" | sort | uniq -c >&2 || true

python3 - "$work" "$repeats" "$cache_mb" <<'PY'
import json, os, statistics, sys
work, repeats, cache_mb = sys.argv[1], int(sys.argv[2]), sys.argv[3]
def load(mode):
    return [json.load(open(f"{work}/{mode}.{r}.json"))[0] for r in range(1, repeats + 1)]
runs = {m: load(m) for m in ("incore", "stack", "sync")}
med = lambda m, key: statistics.median(r[key] for r in runs[m])
t_in, t_st, t_sy = med("incore", "seconds"), med("stack", "seconds"), med("sync", "seconds")
io = med("stack", "loader_busy_seconds")
s = runs["stack"][0]
print(f"cache {cache_mb} MB, {s['threads']} threads, {s['block_count']} blocks, "
      f"{s['rays_total']:,} rays; medians of {repeats} runs (seconds of each run: " +
      "; ".join(f"{m} " + ", ".join(f"{r['seconds']:.2f}" for r in runs[m]) for m in runs) + ")")
print()
print("| mode | seconds | M rays/s | #C loaded | #U used | #C/#U | MB read | loader busy s | ray threads idle s | ray CPU s | loader CPU s | peak stack KB | peak RSS MB |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for m in runs:
    r = runs[m][0]
    print(f"| {m} | {med(m, 'seconds'):.2f} | {med(m, 'rays_per_second')/1e6:.2f} | "
          f"{r['blocks_loaded']:,} | {r['blocks_distinct']:,} | {r['blocks_loaded']/max(1, r['blocks_distinct']):.2f} | "
          f"{r['bytes_read']/2**20:.0f} | {med(m, 'loader_busy_seconds'):.2f} | {med(m, 'ray_idle_seconds'):.2f} | "
          f"{med(m, 'ray_cpu_seconds'):.2f} | {med(m, 'loader_cpu_seconds'):.2f} | "
          f"{r['peak_stack_bytes']/1024:.0f} | {med(m, 'peak_rss_bytes')/2**20:.0f} |")
print()
print(f"- T_sync / T_stack = {t_sy / t_st:.2f}")
print(f"- T_stack / max(T_incore, T_io) = {t_st / max(t_in, io):.2f} (T_incore {t_in:.2f} s, T_io {io:.2f} s; preload of incore excluded)")
print(f"- #C/#U (stack) = {s['blocks_loaded'] / s['blocks_distinct']:.2f}")
# Where the ratio can go on this machine. The stack cannot end before its CPU work is done on
# the cores it has; sync adds the time its threads sit waiting for the disk.
cores = os.cpu_count()
c_stack = med("stack", "ray_cpu_seconds") + med("stack", "loader_cpu_seconds")
c_sync = med("sync", "ray_cpu_seconds")
c_ideal = med("incore", "ray_cpu_seconds") + med("stack", "loader_cpu_seconds")
lanes = min(cores, s["threads"])
print(f"- CPU (kernel included), {cores} cores: stack {c_stack:.2f} s (floor under T_stack "
      f"{c_stack / cores:.2f} s), sync {c_sync:.2f} s; sync's threads waited "
      f"{max(0.0, lanes * t_sy - c_sync):.2f} core-s for the disk")
print(f"- ceiling of T_sync / T_stack here with no stack overhead (ray threads as in core, loads as "
      f"now): {t_sy / (c_ideal / cores):.2f}; at the stack's own CPU: {t_sy / (c_stack / cores):.2f}")
# The same floor bounds the overlap figure from below: T_incore leaves out the blocks' loading,
# which the stack's cores must also do.
print(f"- floor of T_stack / max(T_incore, T_io) at the stack's own CPU: "
      f"{(c_stack / cores) / max(t_in, io):.2f}")
print(f"- bytes per waiting ray: {s['ray_record_bytes']} (record); peak stack {s['peak_stack_bytes']/1024:.0f} KB for "
      f"{s['peak_stack_rays']:,} rays = {s['peak_stack_bytes']/max(1, s['peak_stack_rays']):.0f} bytes/ray with chunk slack")
PY
