#!/usr/bin/env python3
"""Peak memory of volumes read brick by brick (issue 39, item 2): the same volume as raw, NIfTI
and gzipped NIfTI, read by `read_bench windows` (every 64^3 box, the reader alone) and by
`read_bench mlfe` (read_volume, the whole grid), then converted by
`mlfe --threads T convert FILE --iso ISO --bricks 64`, each run in its own process under
/usr/bin/time (peak RSS, wall seconds) with the load average beside it.

  /usr/bin/python3 bench/py/stream_bench.py --build build --out /tmp/stream_bench \\
      /work/data/big/head_250m.raw /work/data/big/head_250m.nii /work/data/big/head_250m.nii.gz

The .nii.gz is made from the .nii with `gzip -6 -c head_250m.nii > head_250m.nii.gz`.
Prints one markdown table; runs one process at a time (each may take gigabytes).
"""
import argparse
import json
import os
import subprocess
import sys


def timed(cmd):
    """Runs cmd under /usr/bin/time; returns (stdout, wall seconds, peak RSS MiB, load before)."""
    load = os.getloadavg()[0]
    p = subprocess.run(["/usr/bin/time", "-f", "@@%M %e"] + cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"failed ({p.returncode}): {' '.join(cmd)}\n{p.stderr}")
    rss, wall = p.stderr.strip().splitlines()[-1][2:].split()
    return p.stdout, float(wall), int(rss) / 1024.0, load


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default="build")
    ap.add_argument("--out", default="/tmp/stream_bench")
    ap.add_argument("--iso", type=float, default=99.5)
    ap.add_argument("--bricks", type=int, default=64)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-convert", action="store_true", help="only the reads")
    ap.add_argument("files", nargs="+")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    read_bench = os.path.join(a.build, "bench", "read_bench")
    mlfe = os.path.join(a.build, "converters", "cli", "mlfe")
    rows = ["| file | run | seconds | peak RSS | load | triangles |", "|---|---|---:|---:|---:|---:|"]
    for f in a.files:
        name = os.path.basename(f)
        for mode in ("windows", "mlfe"):
            _, wall, rss, load = timed([read_bench, mode, f, str(a.bricks)])
            what = f"read every {a.bricks}^3 box" if mode == "windows" else "read whole (read_volume)"
            rows.append(f"| `{name}` | {what} | {wall:.1f} | {rss:.0f} MiB | {load:.1f} | |")
        if a.no_convert:
            continue
        glb, rep = os.path.join(a.out, name + ".glb"), os.path.join(a.out, name + ".json")
        cmd = [mlfe, "--threads", str(a.threads), "convert", f, "--iso", f"{a.iso:g}", "--bricks", str(a.bricks),
               "-o", glb, "--report", rep, "--quiet"]
        _, wall, rss, load = timed(cmd)
        with open(rep) as r:
            report = json.load(r)
        assert report["read_in_windows"], f"{f} was not read in windows"
        rows.append(f"| `{name}` | convert --bricks {a.bricks} | {wall:.1f} | {rss / 1024:.2f} GiB | {load:.1f} | "
                    f"{report['asset']['triangles']:,} |")
        print(rows[-1], file=sys.stderr, flush=True)
    print("\n".join(rows))


if __name__ == "__main__":
    main()
