#!/usr/bin/env python3
"""No shell script that runs under `set -o pipefail` pipes into a reader that may stop early
(`grep -q`, `grep -m`, `head`): the reader exits at its first match, the writer gets SIGPIPE,
and pipefail makes the whole pipeline fail with 141 at random (found by CI: check-package.sh's
`raystack render --help | grep -q` failed a run whose tests had all passed)."""

import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
# After a pipe: grep that may stop early (-q, -m, -l, in any of its flags, or spelled out), head,
# sed that quits, awk that exits.
# (A grep's flags end at the next command: &&, ;, > or a quote.)
EARLY_READER = re.compile(
    r"(?<!\|)\|&?\s*(grep\b[^|;&>'\"]*?\s-[A-Za-z]*[qmlL]"
    r"|grep\b[^|;&>'\"]*--(quiet|silent|max-count|files-with-matches|files-without-match)"
    r"|head\b|sed\s+(-n\s+)?['\"]?\d+q\b|sed\b[^|]*/q['\"]|awk\b[^|]*\bexit\b)")
PIPEFAIL = re.compile(r"^\s*set\s+[^#]*-o\s+pipefail|^\s*set\s+-[A-Za-z]*o\s+pipefail")

# The checker itself, on the forms it must catch and those it must leave (a review found
# `grep -E -q`, `--quiet`, `sed 1q`, `awk exit` and `set -Eeuo pipefail` missed).
for line in ["a | grep -q x", "a | grep -E -q x", "a | grep --quiet x", "a | grep -m1 x",
             "a | grep -l x", "a | grep -L x", "a |& grep -q x", "a | head -n1", "a | sed 1q",
             "a | sed '/x/q'", "a | awk '{print; exit}'"]:
    assert EARLY_READER.search(line), line
for line in ["a || grep -q x", "a | grep -v x", "a | grep -E \"^x-(y|z)$\"", "a | sort",
             "a | awk '{print $1}'", "grep -q x file", "a | grep x && wc -l f",
             "a | grep -i ' -model'", "a | sed 's/v2q/x/'"]:
    assert not EARLY_READER.search(line), line
for line in ["set -euo pipefail", "set -Eeuo pipefail", "set -e -o pipefail",
             "set -o errexit -o pipefail"]:
    assert PIPEFAIL.search(line), line
for line in ["# set -o pipefail", "set +o pipefail"]:
    assert not PIPEFAIL.search(line), line


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
        # A pipe at a line's end continues on the next: joined (numbers stay those of the first).
        lines = re.sub(r"\|[ \t]*\\?\n", "| ", f.read()).splitlines()
    if not any(PIPEFAIL.search(l) for l in lines):
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
