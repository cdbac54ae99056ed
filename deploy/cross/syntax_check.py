#!/usr/bin/python3
"""Checks every program and library source of the host build with another CPU's compiler.

The renderer's libraries (Open MPI, OpenEXR) cannot be installed for arm64 beside the host's on
Debian, so the parts that need them are not cross-built: this runs the other CPU's compiler on
each of their sources (-fsyntax-only: parsing, types, templates instantiated; no code made), so
no x86-only intrinsic or assumption goes unnoticed. It uses the host's headers, the same on
every Debian architecture but for a few configuration files. Tests are left out (the core's are
cross-built and run; the rest are x86 tests of x86 programs).

usage: syntax_check.py COMPILE_COMMANDS.json CROSS_COMPILER
"""
import json
import os
import shlex
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path


def cross_command(entry, compiler):
    """The entry's command for `compiler`, syntax only: no output file, no x86 code options."""
    args = shlex.split(entry["command"])[1:]
    out = [compiler, "-fsyntax-only"]
    skip = False
    for a in args:
        if skip:
            skip = False
        elif a == "-o":
            skip = True
        elif a == "-c" or a.startswith(("-march", "-mavx", "-msse", "-mtune")):
            pass
        else:
            out.append(a)
    return out


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    path, compiler = sys.argv[1], sys.argv[2]
    root = Path(__file__).resolve().parents[2]

    def is_test(source):
        p = Path(source).resolve()
        return p.is_relative_to(root) and p.relative_to(root).parts[0] == "tests"

    entries = [e for e in json.load(open(path)) if not is_test(e["file"])]
    if not entries:
        sys.exit(f"syntax_check: no program or library source in {path}")

    def check(entry):
        r = subprocess.run(cross_command(entry, compiler), cwd=entry["directory"],
                           capture_output=True, text=True)
        return entry["file"], r.returncode, r.stderr

    failed = 0
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        for source, code, stderr in pool.map(check, entries):
            if code != 0 or stderr:
                failed += 1
                print(f"syntax_check: {source} does not pass {compiler}:\n{stderr}")
    print(f"syntax_check: {len(entries) - failed} of {len(entries)} sources pass {compiler}")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
