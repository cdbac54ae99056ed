#!/usr/bin/env bash
# Converter figures for tools/bench/RESULTS.md: per shared model (bytes per triangle, mean
# block size, compression, throughput, peak RSS) and the dragon replicated to 109 M triangles
# under --mem-limit 1024. Prints a Markdown table. Usage:
#   tools/bench/prep_bench.sh [MODELS_DIR] [--big]
set -euo pipefail
cd "$(dirname "$0")/../.."
models=${1:-../shared/models}
prep=build/tools/prep/raystack-prep
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
echo "| model | triangles | blocks | mean raw block KB | largest KB | refs/tri | compression | bytes/tri on disk | seconds | M tri/s | peak RSS MB |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
run() {
  local name=$1; shift
  /usr/bin/time -f "%M" -o "$work/rss" "$prep" "$@" -o "$work/store" -q --stats-json "$work/s.json" > /dev/null 2> "$work/err"
  python3 - "$name" "$work/s.json" "$(cat "$work/rss")" <<'PY'
import json, sys
name, path, rss_kb = sys.argv[1], sys.argv[2], int(sys.argv[3])
s = json.load(open(path))
t = s["triangles"]
print(f"| {name} | {t:,} | {s['blocks']:,} | {s['raw_bytes']/s['blocks']/1024:.1f} | "
      f"{s['largest_raw_block_bytes']/1024:.1f} | {s['references']/t:.3f} | "
      f"{s['raw_bytes']/s['stored_bytes']:.2f} | {s['stored_bytes']/t:.1f} | {s['seconds']:.2f} | "
      f"{s['mtriangles_per_s']:.2f} | {rss_kb/1024:.0f} |")
PY
  rm -rf "$work/store"
}
for m in CornellBox-Original.obj bun_zipper.ply dragon_vrip.ply conference.obj motorBike.obj; do
  run "$m" "$models/$m"
done
run "spheres:2000000 (default scene)" --generate spheres:2000000 --mem-limit 512
if [ "${2:-}" = "--big" ]; then
  run "dragon x125 (5,5,5), --mem-limit 1024" "$models/dragon_vrip.ply" --replicate 5,5,5 --mem-limit 1024
fi
