#!/usr/bin/env bash
# Before/after for the ray engine on this noisy 2-core machine: two raystack builds render the
# same scene in turn, REPEATS times each (interleaved, so a slow moment hits both), and the
# render's own seconds (--stats, preloading excluded) are printed with their mean and median.
#
#   tools/bench/engine_ab.sh BEFORE_BIN AFTER_BIN [SCENE] [REPEATS] [THREADS] [-- render options]
#
# SCENE defaults to scenes/dragon1.json (the Stanford dragon, 1024x768, Whitted, one light;
# see RESULTS.md for its store), rendered --mode incore: this measures the ray core alone.
# Run it under `flock /tmp/raystack-bench.lock`.
set -euo pipefail
cd "$(dirname "$0")/../.."
before=$1 after=$2 scene=${3:-tools/bench/scenes/dragon1.json} repeats=${4:-10} threads=${5:-1}
shift $(( $# >= 5 ? 5 : $# ))
[ "${1:-}" = "--" ] && shift
extra=("$@")
[ ${#extra[@]} -gt 0 ] || extra=(--mode incore)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for r in $(seq 1 "$repeats"); do
  for which in before after; do
    bin=$before; [ $which = after ] && bin=$after
    "$bin" render "$scene" --threads "$threads" -q --no-png --output "$work/out.exr" \
        --stats "$work/stats.json" "${extra[@]}" > /dev/null
    python3 -c "import json,sys; print(sys.argv[1], json.load(open(sys.argv[2]))[0]['seconds'])" \
        "$which" "$work/stats.json" >> "$work/seconds"
  done
done
python3 - "$work/seconds" <<'PY'
import statistics, sys
runs = {}
for line in open(sys.argv[1]):
    which, s = line.split()
    runs.setdefault(which, []).append(float(s))
for which in ("before", "after"):
    s = runs[which]
    print(f"{which}: " + " ".join(f"{x:.3f}" for x in s) +
          f"  mean {statistics.mean(s):.3f}  median {statistics.median(s):.3f}")
b, a = statistics.median(runs["before"]), statistics.median(runs["after"])
print(f"after / before (medians): {a / b:.3f}")
PY
