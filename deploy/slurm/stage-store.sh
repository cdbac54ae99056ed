#!/usr/bin/env bash
# stage-store.sh STORE LOCAL_DIR: copies a block store to node-local disk on every node of the
# current Slurm allocation (one task per node), for `loc` jobs whose shared filesystem is slow.
# Then point the scene's "store" at LOCAL_DIR/<store name> (the same path on every node).
set -euo pipefail
if [ $# -ne 2 ]; then echo "usage: stage-store.sh STORE LOCAL_DIR" >&2; exit 2; fi
store="$1"; dest="$2"
srun --ntasks-per-node=1 --nodes="${SLURM_JOB_NUM_NODES:?run inside an allocation}" \
  bash -c "mkdir -p '$dest' && cp -r '$store' '$dest'/ && echo \"\$(hostname): staged to $dest\""
