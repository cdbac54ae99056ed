#!/usr/bin/env python3
"""No shell script that runs under `set -o pipefail` pipes into a reader that may stop early
(`grep -q`, `grep -m`, `head`): the reader exits at its first match, the writer gets SIGPIPE,
and pipefail makes the whole pipeline fail with 141 at random (found by CI: check-package.sh's
`raystack render --help | grep -q` failed a run whose tests had all passed)."""

import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
EARLY_READER = re.compile(r"(?<!\|)\|\s*(grep\s+-[A-Za-z]*[qm]|head\b)")


def shell_scripts():
    for folder in ("deploy", "tools", "tests", ".ci"):
        for dirpath, _, names in os.walk(os.path.join(ROOT, folder)):
            for name in names:
                path = os.path.join(dirpath, name)
                with open(path, "rb") as f:
                    start = f.read(64)
                if name.endswith((".sh", ".sbatch")) or start.startswith(b"#!/") and b"sh" in start.split(b"\n")[0]:
                    yield path


found = []
checked = 0
for path in shell_scripts():
    with open(path, encoding="utf-8", errors="replace") as f:
        lines = f.read().splitlines()
    if not any(re.match(r"\s*set\s+-[a-z]*o\s+pipefail|\s*set\s+-o\s+pipefail", l) for l in lines):
        continue
    checked += 1
    for number, line in enumerate(lines, 1):
        code = line.split(" #", 1)[0]
        if not code.lstrip().startswith("#") and EARLY_READER.search(code):
            found.append(f"{os.path.relpath(path, ROOT)}:{number}: {line.strip()}")
if checked < 5:
    print(f"FAILED: only {checked} scripts with pipefail found under deploy/, tools/, tests/, .ci/")
    sys.exit(1)
if found:
    print("FAILED: a pipe into a reader that stops early, under pipefail (SIGPIPE, exit 141):")
    print("\n".join(found))
    sys.exit(1)
print(f"{checked} scripts with pipefail: no pipe into grep -q, grep -m or head")
