#!/usr/bin/env bash
# Before/after for the whole job on the emulated cluster: two raystack builds run the same job
# in turn (PAIRS times each, interleaved, so a slow moment of this noisy VM hits both), as
# cluster_bench.sh runs it: N slaves under mpirun, each capped at QUOTA percent of a core
# (cpu_capped.sh; QUOTA 0: no cap), one ray thread each, a 24 MB block cache. Prints each
# run's frame seconds, the slaves' CPU seconds per frame and the median over slaves of the
# wait for the frame's first tile (from the slave starting the frame), then the medians per
# build.
#
#   tools/bench/cluster_ab.sh PAIRS N BLOCKS BEFORE_BIN AFTER_BIN [SCENE] [QUOTA] [-- render options]
#
# BLOCKS is loc or rem; SCENE defaults to scenes/default2.json (two frames of one view), QUOTA
# to 20. Extra render options follow `--` (e.g. -- --convergence-log log.csv --reference ref.exr). Run it under
# `flock /tmp/raystack-bench.lock`.
set -euo pipefail
cd "$(dirname "$0")/../.."
pairs=$1 n=$2 blocks=$3 before=$4 after=$5 scene=${6:-tools/bench/scenes/default2.json}
quota=${7:-20}
shift $(( $# >= 7 ? 7 : $# ))
[ "${1:-}" = "--" ] && shift
extra=("$@")
work=$(mktemp -d)
trap 'rm -rf "$work"; rmdir /sys/fs/cgroup/cpu/raystack_bench_r* 2>/dev/null || true' EXIT
cap=()
[ "$quota" != 0 ] && cap=(-x RAYSTACK_CPU_QUOTA_PCT tools/bench/cpu_capped.sh)
for p in $(seq 1 "$pairs"); do
  for which in before after; do
    bin=$before; [ $which = after ] && bin=$after
    RAYSTACK_CPU_QUOTA_PCT=$quota mpirun --allow-run-as-root --oversubscribe -np $((n + 1)) \
        "${cap[@]}" "$bin" render "$scene" --threads 1 --cache-mb 24 --blocks "$blocks" \
        --no-png -q --output "$work/out.exr" --stats "$work/stats.json" ${extra[@]+"${extra[@]}"} \
        > /dev/null
    python3 - "$which" "$work/stats.json" >> "$work/runs" <<'PY'
import json, statistics, sys
frames = json.load(open(sys.argv[2]))
def first_tile(f):  # engine time before the first tile (see cluster_bench.sh)
    return statistics.median(max(0.0, s["engine_seconds"] - s["seconds"]) for s in f["slaves"])
print(sys.argv[1], json.dumps({"seconds": [f["seconds"] for f in frames],
                               "cpu": [sum(s["process_cpu_seconds"] for s in f["slaves"]) for f in frames],
                               "first_tile": [first_tile(f) for f in frames]}))
PY
    tail -n 1 "$work/runs"
  done
done
python3 - "$work/runs" <<'PY'
import json, statistics, sys
runs = {}
for line in open(sys.argv[1]):
    which, data = line.split(" ", 1)
    runs.setdefault(which, []).append(json.loads(data))
for which in ("before", "after"):
    r = runs[which]
    med = lambda key: " / ".join("%.3f" % statistics.median(x[key][i] for x in r)
                                 for i in range(len(r[0][key])))
    print(f"{which}: frames {med('seconds')} s; slaves' CPU {med('cpu')} s; "
          f"first tile {med('first_tile')} s (medians of {len(r)})")
PY
