#!/usr/bin/env bash
# stage-store.sh STORE LOCAL_DIR: copies a block store to node-local disk on every node of the
# current Slurm allocation (one task per node), for `loc` jobs whose shared filesystem is slow.
# Then point the scene's "store" at LOCAL_DIR/<store name> (the same path on every node).
# Each node checks that its copy has every file at its full size (a full local disk truncates
# a copy); a copy that still differs (another store left at that path) is named by the master
# when the job starts: it compares every slave's store index.
set -euo pipefail
if [ $# -ne 2 ]; then echo "usage: stage-store.sh STORE LOCAL_DIR" >&2; exit 2; fi
# The paths go to the nodes as arguments, never inside the command's text (quotes in a path).
srun --ntasks-per-node=1 --nodes="${SLURM_JOB_NUM_NODES:?run inside an allocation}" \
  bash -c '
    set -euo pipefail
    store=$1; dest=$2; copy="$dest/$(basename "$store")"
    mkdir -p "$dest"
    if [ "$(realpath "$store")" = "$(realpath -m "$copy")" ]; then
      echo "$(hostname): $copy is the store itself: give a LOCAL_DIR other than its folder" >&2
      exit 2
    fi
    # Copied aside, then moved into place: an old copy is replaced whole, never mixed.
    rm -rf "$copy.staging"
    cp -r "$store" "$copy.staging"
    rm -rf "$copy"
    mv "$copy.staging" "$copy"
    for f in blocks.bin index.bin octree.bin lights.bin; do
      # (lights.bin: a store written before it has none)
      if [ "$f" = lights.bin ] && [ ! -e "$store/$f" ]; then continue; fi
      if [ "$(stat -c %s "$store/$f")" != "$(stat -c %s "$copy/$f")" ]; then
        echo "$(hostname): $copy/$f: copied short (disk full?)" >&2
        exit 1
      fi
    done
    echo "$(hostname): staged to $copy"
  ' stage-store "$1" "$2"
