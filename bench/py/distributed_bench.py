#!/usr/bin/python3
"""distributed_bench.py: one volume converted by one process against Dask workers, in one run.

Rows, each on the same volume, iso-value and brick edge (the command line's auto rule unless
--bricks), the asset a .glb:
  * `mlfe convert VOL --iso ISO` at --threads 1 and 2 (one process; seconds and peak RSS from
    /usr/bin/time);
  * mlfe.distributed.convert on a LocalCluster of 1 and of 2 worker processes, one thread each
    (threads_per_worker=1); the whole call timed, cluster start-up excluded (it is made first);
    peak RSS of the client (this run's own process) and of each worker (ru_maxrss, asked of the
    workers before the cluster closes). The 1-worker row runs pinned to one core (the workers
    inherit the affinity, and the library's threads inside a brick follow it), as --threads 1;
    the 2-worker row on two cores.
Every distributed output is compared with the command line's (the bytes must be equal). Each
row runs in a fresh process (`--row NAME`), so peaks do not carry over; the load average is
recorded beside every row.

usage: bench/py/distributed_bench.py [--build DIR] [--bricks N] [--rows cli-2,dask-1,dask-2] [--json OUT]
                                     [--work DIR] VOL ISO
Uses /usr/bin/python3 with python3-distributed; PYTHONPATH is set to <build>/python for the rows.
"""
import argparse
import filecmp
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_paths import mlfe_binary  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ROWS = ("cli-1", "cli-2", "dask-1", "dask-2")  # cli-N: --threads N; dask-N: N workers


def load():
    with open("/proc/loadavg") as f:
        return " ".join(f.read().split()[:3])


def run_cli(args, threads, out):
    cmd = ["/usr/bin/time", "-f", "@@%M", mlfe_binary(args.build), "--threads", str(threads), "convert", args.volume,
           "--iso", str(args.iso), "-o", out]
    if args.bricks:
        cmd += ["--bricks", str(args.bricks)]
    start = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if p.returncode != 0:
        raise RuntimeError("%s failed: %s" % (" ".join(cmd), p.stderr[-2000:]))
    peak = [line for line in p.stderr.splitlines() if line.startswith("@@")][-1]
    return {"seconds": seconds, "peak_mb": int(peak[2:]) / 1024.0}


def peak_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_dask(args, workers, out):
    """In this (fresh) process: the call on a LocalCluster of `workers` processes."""
    import distributed
    import mlfe.distributed

    os.sched_setaffinity(0, set(range(workers)))  # before the workers start: they inherit it
    options = {"bricks": args.bricks} if args.bricks else {}
    with distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        start = time.perf_counter()
        summary = mlfe.distributed.convert(args.volume, out, client, iso=args.iso, **options)
        seconds = time.perf_counter() - start
        worker_peaks = sorted(client.run(peak_mb).values())
    return {"seconds": seconds, "peak_mb": peak_mb(), "worker_peak_mb": worker_peaks,
            "triangles": summary["triangles"]}


def row(args, name, out):
    kind, count = name.split("-")
    return run_cli(args, int(count), out) if kind == "cli" else run_dask(args, int(count), out)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("volume")
    p.add_argument("iso", type=float)
    p.add_argument("--build", default=os.path.join(ROOT, "build"))
    p.add_argument("--bricks", type=int, default=0, help="brick edge (0: the command line's auto rule)")
    p.add_argument("--json", help="also write the rows here")
    p.add_argument("--work", help="folder for the outputs (default: a temporary one)")
    p.add_argument("--rows", default=",".join(ROWS), help="which rows, in order (default: all)")
    p.add_argument("--row", choices=ROWS, help=argparse.SUPPRESS)  # one row, in a fresh process
    p.add_argument("--out", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.row:
        print(json.dumps(row(args, args.row, args.out)))
        return

    env = dict(os.environ, PYTHONPATH=os.path.join(args.build, "python"))
    with tempfile.TemporaryDirectory(dir=args.work) as work:
        results = []
        names = args.rows.split(",")
        unknown = sorted(set(names) - set(ROWS))
        if unknown or not names[0].startswith("cli"):
            p.error("--rows: %s of %s, a cli row first (the bytes and the times are compared with it)" %
                    (",".join(names), ",".join(ROWS)))
        for name in names:
            out = os.path.join(work, name + ".glb")
            before = load()
            cmd = [sys.executable, os.path.abspath(__file__), args.volume, str(args.iso), "--build", args.build,
                   "--bricks", str(args.bricks), "--row", name, "--out", out]
            r = subprocess.run(cmd, capture_output=True, text=True, env=env)
            if r.returncode != 0:
                raise RuntimeError("%s failed: %s" % (name, r.stderr[-3000:]))
            result = json.loads(r.stdout.strip().splitlines()[-1])
            result.update(row=name, load_before=before, load_after=load(), bytes=os.path.getsize(out),
                          same_bytes_as_cli=filecmp.cmp(out, os.path.join(work, names[0] + ".glb"), shallow=False))
            results.append(result)
            print(json.dumps(result), flush=True)
    base = results[0]["seconds"]
    print("\n| row | seconds | speed-up over %s | peak MB (client) | peak MB (workers) | same bytes | load avg "
          "before/after |" % names[0])
    print("|---|---|---|---|---|---|---|")
    for r in results:
        workers = ", ".join("%.0f" % w for w in r.get("worker_peak_mb", [])) or "-"
        print("| %s | %.1f | %.2f | %.0f | %s | %s | %s / %s |" % (r["row"], r["seconds"], base / r["seconds"],
                                                                   r["peak_mb"], workers, r["same_bytes_as_cli"],
                                                                   r["load_before"], r["load_after"]))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
