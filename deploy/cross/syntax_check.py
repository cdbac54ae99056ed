#!/usr/bin/python3
"""Compiles every source of the host build for another CPU, syntax only.

The renderer's libraries (Open MPI, OpenEXR) cannot be installed for arm64 beside the host's on
Debian, so the parts that need them are not cross-built: this checks that each of their sources
still compiles for the other CPU (no x86-only intrinsic or assumption), with the host's
headers, which are the same on every Debian architecture but for a few configuration files.

usage: syntax_check.py COMPILE_COMMANDS.json CROSS_COMPILER
"""
import json
import os
import shlex
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor


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
    entries = [e for e in json.load(open(path)) if "/tests/" not in e["file"]]

    def check(entry):
        r = subprocess.run(cross_command(entry, compiler), cwd=entry["directory"],
                           capture_output=True, text=True)
        return entry["file"], r.returncode, r.stderr

    failed = 0
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        for source, code, stderr in pool.map(check, entries):
            if code != 0 or stderr:
                failed += 1
                print(f"syntax_check: {source} does not compile for {compiler}:\n{stderr}")
    print(f"syntax_check: {len(entries) - failed} of {len(entries)} sources compile for {compiler}")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
