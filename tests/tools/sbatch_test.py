#!/usr/bin/env python3
"""deploy/slurm/raystack.sbatch as Slurm runs it, with a stand-in srun that prints its command
line: the cache each task is given from Slurm's memory figures, and srun's CPUs per task.
(Found by an operator: each of a node's tasks took 3/4 of the node's memory, and srun, which no
longer inherits --cpus-per-task from sbatch since Slurm 22.05, ran each task on one CPU.)"""

import os
import subprocess
import sys
import tempfile

SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "deploy", "slurm",
                      "raystack.sbatch")


def run(env):
    with tempfile.TemporaryDirectory() as bin_dir:
        srun = os.path.join(bin_dir, "srun")
        with open(srun, "w") as f:
            f.write('#!/bin/sh\necho "srun $*"\n')
        os.chmod(srun, 0o755)
        full = {"PATH": bin_dir + ":" + os.environ["PATH"]}
        full.update(env)
        out = subprocess.run(["bash", SCRIPT, "scene.json"], env=full, capture_output=True,
                             text=True, check=True).stdout
        return [line for line in out.splitlines() if line.startswith("srun ")][0]


def expect(condition, what):
    if not condition:
        print("FAILED:", what)
        sys.exit(1)


line = run({"SLURM_MEM_PER_NODE": "64000", "SLURM_NTASKS_PER_NODE": "2", "SLURM_CPUS_PER_TASK": "8"})
expect("--cache-mb 24000 " in line, "two tasks on a 64 GB node take 3/4 of 32 GB each: " + line)
expect("--cpus-per-task=8 " in line, "srun is given the CPUs per task: " + line)
line = run({"SLURM_MEM_PER_NODE": "64000", "SLURM_NTASKS": "5", "SLURM_JOB_NUM_NODES": "4"})
expect("--cache-mb 24000 " in line, "5 tasks on 4 nodes: up to 2 a node: " + line)
expect("--cpus-per-task" not in line, "no CPUs per task asked, none given: " + line)
line = run({"SLURM_MEM_PER_CPU": "4000", "SLURM_CPUS_PER_TASK": "4"})
expect("--cache-mb 12000 " in line, "memory per CPU times CPUs per task: " + line)
line = run({"SLURM_MEM_PER_NODE": "64000", "RAYSTACK_CACHE": "100"})
expect("--cache-mb 100 " in line, "RAYSTACK_CACHE wins: " + line)
print("sbatch_test: ok")
