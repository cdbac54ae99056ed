#!/usr/bin/env bash
# What watching costs: the same render without the preview, with the preview on and nobody
# watching, and with a headless Chromium showing the page the whole time (960x540, 4 spp path
# tracing, 2 ray threads, one process). Prints each run's wall and CPU time and the preview's
# own figures (frames sent / skipped). Run it under flock /tmp/raystack-bench.lock on a shared
# machine.
#   tools/bench/preview_bench.sh [BUILD_DIR] [REPEATS]
set -euo pipefail
build=${1:-build}
repeats=${2:-3}
work=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$work"' EXIT
"$build/tools/prep/raystack-prep" --generate spheres:200000 -o "$work/store" -q > /dev/null
cat > "$work/scene.json" <<JSON
{ "store": "$work/store",
  "camera": { "position": [0, 2, 6], "look_at": [0, 0, 0], "fov_y_deg": 45, "width": 960, "height": 540 },
  "lights": [ { "type": "point", "position": [4, 9, 6], "intensity": [160, 150, 140] } ],
  "materials": { "default": { "type": "diffuse", "albedo": [0.75, 0.72, 0.68] } },
  "background": [0.05, 0.06, 0.09],
  "integrator": { "type": "path", "max_depth": 3, "spp": 4, "seed": 1 },
  "output": "$work/out.exr" }
JSON
# Wall seconds, and the render's own CPU seconds (user + system: its ray threads and the
# preview server, not Chromium, which on this 2-core machine competes for the same cores).
render() {  # extra options...
  /usr/bin/time -f "%e s wall, %U+%S s CPU" -o "$work/time" \
    "$build/master/raystack" render "$work/scene.json" --threads 2 --no-png -q "$@" > "$work/log" 2>&1
  cat "$work/time"
}
for r in $(seq "$repeats"); do
  echo "run $r: no preview           $(render)"
  echo "run $r: preview, no viewer   $(render --preview 47311)"
  # A viewer: Chromium opens the page as soon as the port answers, and stays until the end.
  (
    for _ in $(seq 200); do curl -s -o /dev/null "http://127.0.0.1:47312/" && break; sleep 0.02; done
    exec chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
      --disable-background-networking --disable-component-update --disable-sync \
      --user-data-dir="$work/profile-$r" --remote-debugging-port=0 "http://127.0.0.1:47312/" \
      > "$work/chromium.log" 2>&1
  ) &
  viewer=$!
  echo "run $r: preview + Chromium  $(render --preview 47312)   ($(grep 'frames sent' "$work/log" | sed 's/preview: //'))"
  kill "$viewer" 2>/dev/null || true
  wait "$viewer" 2>/dev/null || true
done
