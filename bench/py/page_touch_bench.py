#!/usr/bin/python3
"""page_touch_bench.py: what first touching fresh anonymous memory costs on this machine.

The render set-up and frame write some 100-300 MB of new arrays (bench/RESULTS.md, "Opening a
hierarchy"); on a virtual machine each new page may cost a fault in the guest and one in the
host. This maps MB megabytes (anonymous, private), optionally asks for transparent huge pages
(madvise MADV_HUGEPAGE, as mlfe's advise_huge_pages does), writes one byte per 4 KiB page and
reports the milliseconds, for --repeat maps in a row (the later ones reuse pages the kernel has
just been given back), then again after --pause seconds.

usage: bench/py/page_touch_bench.py [--mb 168] [--repeat 3] [--pause 3] [--no-huge]
"""
import argparse
import mmap
import time


def touch(mb, huge):
    n = mb << 20
    m = mmap.mmap(-1, n + (2 << 20), flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    if huge:
        m.madvise(mmap.MADV_HUGEPAGE)
    t0 = time.perf_counter()
    for i in range(0, n, 4096):
        m[i] = 1
    ms = (time.perf_counter() - t0) * 1e3
    m.close()
    return ms


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mb", type=int, default=168)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--pause", type=float, default=3.0)
    ap.add_argument("--no-huge", action="store_true")
    a = ap.parse_args()
    # The loop itself (a write per page in Python), on pages already mapped, for reference.
    n = a.mb << 20
    m = mmap.mmap(-1, n, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    for i in range(0, n, 4096):
        m[i] = 1
    t0 = time.perf_counter()
    for i in range(0, n, 4096):
        m[i] = 2
    loop = (time.perf_counter() - t0) * 1e3
    m.close()
    huge = not a.no_huge
    first = [touch(a.mb, huge) for _ in range(a.repeat)]
    time.sleep(a.pause)
    later = [touch(a.mb, huge) for _ in range(a.repeat)]
    print("%d MB, %s pages: first touch %s ms; after %.0f s: %s ms (loop alone %.1f ms)" % (
        a.mb, "huge" if huge else "4 KiB", " / ".join("%.0f" % x for x in first), a.pause,
        " / ".join("%.0f" % x for x in later), loop))


if __name__ == "__main__":
    main()
