#!/usr/bin/env python3
"""The default `mlfe build` of a volume, binaries interleaved (issue #23: build ≤ 10 s, ≤ 1.5 GB).

Runs `/usr/bin/time -v MLFE --threads T build VOLUME -o OUT.mlfeh --report OUT.json` for every
binary in turn, ROUNDS times (interleaved, so a shared machine's load falls on all alike), and
prints a Markdown table per run: wall, user and system seconds and peak RSS from time(1), the
per-iteration assembly seconds, the encoding seconds and the file's size from the report, and
whether the file is byte-identical to the first binary's.

Usage: /usr/bin/python3 bench/py/build_default_bench.py --mlfe base=/work/main/build/converters/cli/mlfe
           --mlfe new=build/converters/cli/mlfe --volume /work/data/fullhead_1mm.nii.gz [--threads 2]
           [--rounds 2] [--out /tmp/build_default_bench]
"""
import argparse
import filecmp
import json
import os
import re
import subprocess


def run(label, binary, volume, threads, out, rnd):
    stem = os.path.join(out, f"{label}_{rnd}")
    cmd = ["/usr/bin/time", "-v", binary, "--threads", str(threads), "build", volume, "-o", stem + ".mlfeh",
           "--report", stem + ".json"]
    p = subprocess.run(cmd, capture_output=True, text=True, check=True)
    t = p.stderr

    def field(name):
        return re.search(re.escape(name) + r":\s*(\S+)", t).group(1)

    wall = field("Elapsed (wall clock) time (h:mm:ss or m:ss)").split(":")
    secs = sum(float(x) * 60 ** i for i, x in enumerate(reversed(wall)))
    with open(stem + ".json") as f:
        rep = json.load(f)
    it = rep["per_iteration"]
    return {
        "label": label,
        "file": stem + ".mlfeh",
        "wall": secs,
        "user": float(field("User time (seconds)")),
        "sys": float(field("System time (seconds)")),
        "peak_gb": int(field("Maximum resident set size (kbytes)")) * 1024 / 1e9,
        "assembly": [x["assembly_seconds"] for x in it],
        "refine": sum(x.get("refine_seconds", 0) for x in it),
        "solve": sum(x["solve_seconds"] for x in it),
        "encode": rep["file"]["encode_seconds"],
        "bytes": int(rep["file"]["bytes"]),
        "vertices": rep["vertices"],
        "leaves": rep["elements"],
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mlfe", action="append", required=True, help="LABEL=PATH, first is the reference")
    ap.add_argument("--volume", required=True)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", default="/tmp/build_default_bench")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    bins = [m.split("=", 1) for m in a.mlfe]
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    print("| round | binary | wall s | user s | sys s | peak GB | assembly s per iteration (sum) "
          "| refine s | solve s | encode s | bytes | same bytes |")
    print("|---|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---|")
    for rnd in range(a.rounds):
        ref = None
        for label, binary in bins:
            r = run(label, binary, a.volume, a.threads, a.out, rnd)
            ref = ref or r["file"]
            same = filecmp.cmp(ref, r["file"], shallow=False)
            asm = " / ".join(f"{x:.2f}" for x in r["assembly"])
            print(f"| {rnd} | {label} | {r['wall']:.1f} | {r['user']:.1f} | {r['sys']:.1f} | {r['peak_gb']:.2f} "
                  f"| {asm} ({sum(r['assembly']):.1f}) | {r['refine']:.1f} | {r['solve']:.1f} "
                  f"| {r['encode']:.1f} | {r['bytes']} | {'yes' if same else 'NO'} |", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}; "
          f"{r['vertices']} vertices, {r['leaves']} leaves")


if __name__ == "__main__":
    main()
