#!/usr/bin/env python3
"""What first-touching memory costs on this machine (tools/bench/RESULTS.md, "Memory new to the
guest"). Maps MB of anonymous memory, makes it resident (a write per 4 KB page, or one
madvise(MADV_POPULATE_WRITE)), unmaps it, ROUNDS times, with PAUSE seconds between rounds, and
prints MB/s per round. On a VM whose balloon driver reports free memory to the host (Linux
page reporting, /sys/module/page_reporting), memory freed a few seconds ago is new to the guest
again and costs the host's backing; memory freed just before does not.

  tools/bench/fresh_memory_probe.py [--mb 256] [--rounds 3] [--pause 0] [--huge] [--populate]
"""
import argparse
import mmap
import time

MADV_POPULATE_WRITE = 23  # Linux 5.14; not in Python's mmap constants


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mb", type=int, default=256, help="memory per round (default 256)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds (default 3)")
    ap.add_argument("--pause", type=float, default=0, help="seconds between rounds (default 0)")
    ap.add_argument("--huge", action="store_true", help="madvise(MADV_HUGEPAGE) first")
    ap.add_argument("--populate", action="store_true",
                    help="one madvise(MADV_POPULATE_WRITE) instead of a write per page")
    a = ap.parse_args()
    size = a.mb << 20
    for r in range(a.rounds):
        if r and a.pause:
            time.sleep(a.pause)
        m = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
        start = time.perf_counter()
        if a.huge:
            m.madvise(mmap.MADV_HUGEPAGE)
        if a.populate:
            m.madvise(MADV_POPULATE_WRITE)
        else:
            for page in range(0, size, 4096):
                m[page] = 1
        seconds = time.perf_counter() - start
        m.close()
        print(f"round {r}: {a.mb} MB in {seconds * 1e3:.0f} ms, {a.mb / seconds:.0f} MB/s "
              f"({'huge pages' if a.huge else '4 KB pages'}, "
              f"{'populated' if a.populate else 'written'})")


if __name__ == "__main__":
    main()
