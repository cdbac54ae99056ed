#!/usr/bin/env bash
# raystack-demo [DIR]: the built-in default scene with the installed programs. Generates the
# 2 M-triangle scene into a block store in DIR (default ./raystack-demo), checks every block,
# and renders it under mpirun on this machine (1 master + 2 slaves, 16 MiB block cache each,
# smaller than the store): DIR/default.exr and DIR/default.png.
set -euo pipefail
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then
  sed -n '2,5p' "$0" | sed 's/^# \{0,1\}//'
  exit 0
fi
dir="${1:-raystack-demo}"
bin="$(cd "$(dirname "$(readlink -f "$0")")" && pwd)"
share="$bin/../share/raystack"
mkdir -p "$dir"
"$bin/raystack-prep" --generate spheres:2000000 -o "$dir/default-store" --mem-limit 512
"$bin/raystack-info" "$dir/default-store" --verify
# The scene names its store and output relative to itself.
sed -e 's#"../build/default-store"#"default-store"#' -e 's#"../build/default.exr"#"default.exr"#' \
    "$share/default-scene.json" > "$dir/default-scene.json"
as_root=()
if [ "$(id -u)" = 0 ]; then as_root=(--allow-run-as-root); fi
mpirun "${as_root[@]}" --oversubscribe -np 3 \
    "$bin/raystack" render "$dir/default-scene.json" --threads 1 --cache-mb 16
echo "raystack-demo: wrote $dir/default.exr"
