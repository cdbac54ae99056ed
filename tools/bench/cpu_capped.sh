#!/usr/bin/env bash
# Runs one MPI rank inside a cgroup-v1 CPU group of its own capped at RAYSTACK_CPU_QUOTA_PCT
# percent of one core (ranks >= 1 only; the master runs uncapped): an emulated cluster node on
# this 2-core machine. Used by cluster_bench.sh as the program mpirun launches.
set -euo pipefail
rank=${OMPI_COMM_WORLD_RANK:-0}
if [ "$rank" -gt 0 ] && [ -n "${RAYSTACK_CPU_QUOTA_PCT:-}" ]; then
  group=/sys/fs/cgroup/cpu/raystack_bench_r$rank
  mkdir -p "$group"
  # A 10 ms period (not the default 100 ms): a group that used its share is frozen for the
  # rest of the period, and a node frozen for 80 ms cannot answer its peers (--blocks rem).
  # RAYSTACK_CPU_PERIOD_US changes it (the quota follows: QUOTA_PCT of each period).
  period=${RAYSTACK_CPU_PERIOD_US:-10000}
  echo -1 > "$group/cpu.cfs_quota_us"
  echo "$period" > "$group/cpu.cfs_period_us"
  echo $((RAYSTACK_CPU_QUOTA_PCT * period / 100)) > "$group/cpu.cfs_quota_us"
  echo $$ > "$group/cgroup.procs"
fi
exec "$@"
