#!/usr/bin/python3
"""render_e2e_bench.py: `mlfe render H.mlfeh` end to end against the grid it came from (#27).

In one run, on one volume VOL and its hierarchies H1, H2, ... (built beforehand with
`mlfe build VOL -o H --max-vertices N` or the default; not timed here), with 2 threads:
  * set-up: the wall time of `mlfe render X -o x.exr --size 1x1` (reading, decoding, the level
    rebuild and the render structures; the one ray costs nothing), X = VOL --reference (the
    scan read) or H; best of --repeat processes;
  * end to end: the wall time of the same command at --size (default 500x500), best of
    --repeat, and per frame: the render time the command reports;
  * the same for a baseline build of mlfe (--base-build DIR: the commit before the change),
    so before/after figures come from the same run;
  * progressive: `mlfe render H --level K` for every level K of the first hierarchy (reads the
    file's prefix up to level K): end-to-end time, vertices of T_K (from `mlfe info`), PSNR
    against the reference image (like Table 3 of Grosso, Lürig & Ertl 1997);
  * VTK 9's vtkFixedPointVolumeRayCastMapper on the voxel grid, same camera (orthographic),
    size and transfer function (the setup of bench/py/render_bench.py), sample distance 1 voxel
    and half a voxel: per-frame time (best after the first render).
PSNR: RGBA premultiplied against `mlfe render VOL --reference`, peak 1 (render_bench psnr).
The machine may be shared: compare ratios within one run, not across runs.
With --rounds N, instead: N interleaved rounds of the set-up and end-to-end commands of the
reference, every hierarchy with this build and (with --base-build) the base, one process each
in turn (in a new seeded order every round), reporting per command the minimum and median wall time, the median CPU time (user +
system, from the process's own rusage: less sensitive to other load than wall time) and the
peak resident memory; `cmp` of each hierarchy's image against the base's.
With --turntable N, instead: the per-frame time once the render structures exist, as VTK's
"best after the first" is: `mlfe render H --frames N` (azimuths 0, 360/N, ...; frame 0 also
builds the step records) against VTK fixed point at each of the same views (best of --repeat
after its first render), for the first hierarchy and the reference, each view's ratio and
their median over frames 1..N-1.

usage: bench/py/render_e2e_bench.py VOL H1.mlfeh [H2.mlfeh ...] [--base-build DIR] [--size WxH]
       [--repeat N] [--rounds N] [--turntable N] [--no-vtk] [--no-levels] [--work DIR] [--json OUT]
"""
import argparse
import json
import os
import random
import re
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)
import render_bench  # noqa: E402  (VTK_CHILD: the VTK side, shared with the older bench)
from bench_paths import mlfe_binary  # noqa: E402


def run_mlfe(mlfe, args, repeat):
    """Best wall time of `repeat` processes and the render time the best one reported."""
    best, frame, stats = 1e9, None, ""
    for _ in range(repeat):
        t0 = time.perf_counter()
        p = subprocess.run([mlfe, "--threads", "2"] + args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                           text=True)
        wall = time.perf_counter() - t0
        if p.returncode != 0:
            raise RuntimeError("mlfe %s failed: %s" % (" ".join(args), p.stderr[-2000:]))
        m = re.search(r"in ([0-9.]+) s, (.*) ->", p.stderr)
        if wall < best:
            best, frame, stats = wall, float(m.group(1)), m.group(2)
    return {"wall_s": best, "frame_s": frame, "stats": stats}


def run_once(mlfe, args):
    """Wall time, CPU time (user + system) and peak RSS (MB) of one process."""
    t0 = time.perf_counter()
    p = subprocess.Popen([mlfe, "--threads", "2"] + args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    err = p.stderr.read().decode()
    _, status, ru = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError("mlfe %s failed: %s" % (" ".join(args), err[-2000:]))
    m = re.search(r"in ([0-9.]+) s, ", err)
    return {"wall_s": wall, "cpu_s": ru.ru_utime + ru.ru_stime, "rss_mb": ru.ru_maxrss / 1024.0,
            "frame_s": float(m.group(1)) if m else None}


def frame_times(mlfe, args):
    """Per-frame render times of one `mlfe render --frames` process, in frame order."""
    p = subprocess.run([mlfe, "--threads", "2"] + args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        raise RuntimeError("mlfe %s failed: %s" % (" ".join(args), p.stderr[-2000:]))
    return [float(x) for x in re.findall(r"in ([0-9.]+) s, ", p.stderr)]


def vtk_env():
    """The environment for VTK's off-screen window, and the Xvfb started for it (or None)."""
    env = dict(os.environ, OMP_NUM_THREADS="2")
    if "DISPLAY" in env:
        return env, None
    xvfb = subprocess.Popen(["Xvfb", ":88", "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.5)
    env["DISPLAY"] = ":88"
    return env, xvfb


def vtk_setup(a, helper, az, w, h, prefix):
    """render_bench's set-up (the grid as raw floats, camera, transfer function) of the view at
    azimuth az, written beside prefix; returns it and its path."""
    setup = json.loads(subprocess.run([helper, "setup", a.volume, a.hierarchies[0], str(az), "0", str(w), str(h),
                                       a.tf, prefix], capture_output=True, text=True, check=True).stdout)
    path = prefix + "_setup.json"
    with open(path, "w") as f:
        json.dump(setup, f)
    return setup, path


def vtk_render(a, env, setup_path, prefix, w, h, dist, png):
    """VTK fixed point on that set-up at sample distance dist: its JSON line, or {"error": ...}."""
    cfg = dict(kind="fixed", setup=setup_path, size=[w, h], repeat=a.repeat, raw=prefix + ".raw",
               sample_distance=dist, png=png)
    p = subprocess.run([sys.executable, "-c", render_bench.VTK_CHILD, json.dumps(cfg)],
                       capture_output=True, text=True, env=env)
    return (json.loads(p.stdout.strip().splitlines()[-1]) if p.returncode == 0 else
            {"error": (p.stderr.strip().splitlines() or ["failed"])[-1]})


def turntable(a, mlfe, helper, w, h):
    """--turntable: steady per-frame times, mlfe's turntable against VTK at the same views."""
    n = a.turntable
    H = a.hierarchies[0]
    common = ["--frames", str(n), "--size", a.size, "--azimuth", "0", "--elevation", "0", "--tf", a.tf]
    out = {"frames": n}
    for tag, src, extra in (("mesh", H, []), ("reference", a.volume, ["--reference"])):
        best = None
        for _ in range(a.repeat):
            t = frame_times(mlfe, ["render", src, "-o", os.path.join(a.work, "tt_%s.exr" % tag)] + common + extra)
            best = t if best is None else [min(x, y) for x, y in zip(best, t)]
        out[tag] = best
    env, xvfb = vtk_env()
    try:
        vtk_times = []
        for k in range(n):
            prefix = os.path.join(a.work, "vtk_tt%d" % k)
            setup, path = vtk_setup(a, helper, 360.0 * k / n, w, h, prefix)
            r = vtk_render(a, env, path, prefix, w, h, 1.0 * min(setup["spacing"]), prefix + ".png")
            if "error" in r:
                raise RuntimeError("VTK at frame %d: %s" % (k, r["error"]))
            vtk_times.append(r["render_s"])
        out["vtk_fixed_1voxel"] = vtk_times
    finally:
        if xvfb:
            xvfb.terminate()
            xvfb.wait()
    med = lambda xs: sorted(xs)[len(xs) // 2]
    print("%-6s %10s %10s %10s %12s" % ("frame", "azimuth", "mesh s", "VTK 1vx s", "reference s"))
    for k in range(n):
        print("%-6d %10.1f %10.3f %10.3f %12.3f" % (k, 360.0 * k / n, out["mesh"][k], out["vtk_fixed_1voxel"][k],
                                                     out["reference"][k]))
    later = range(1, n)
    out["median_mesh_over_vtk"] = med([out["mesh"][k] / out["vtk_fixed_1voxel"][k] for k in later])
    out["median_mesh_over_reference"] = med([out["mesh"][k] / out["reference"][k] for k in later])
    print("frames 1..%d, median ratio: mesh / VTK %.2f, mesh / reference %.2f" %
          (n - 1, out["median_mesh_over_vtk"], out["median_mesh_over_reference"]))
    return out


def interleaved(a, builds, view):
    """--rounds: every command once per round, in turn; minimum and median per command."""
    cmds = [("reference/%s" % bname, binary, a.volume, ["--reference"]) for bname, binary in builds]
    for H in a.hierarchies:
        for bname, binary in builds:
            cmds.append(("%s/%s" % (os.path.basename(H), bname), binary, H, []))
    samples = {}
    for rnd in range(a.rounds):
        # A new order every round (seeded): on the VMs measured, a process that follows a small
        # one pays for first-touching its memory again at the host (0.3-0.5 s of system time for
        # H225k's 331 MB after the reference's 48 MB), one that follows a big one does not; a
        # fixed order charged that to the same commands every round.
        order = list(cmds)
        random.Random(rnd).shuffle(order)
        for tag, binary, src, extra in order:
            for size in ("1x1", a.size):
                out = os.path.join(a.work, "%s_%s.exr" % (tag.replace("/", "_"), size))
                r = run_once(binary, ["render", src, "-o", out, "--size", size] + view + extra)
                samples.setdefault((tag, size), []).append(r)
        print("round %d done" % (rnd + 1), file=sys.stderr, flush=True)
    med = lambda xs: sorted(xs)[len(xs) // 2]
    res = {}
    for (tag, size), rs in samples.items():
        res["%s %s" % (tag, size)] = {
            "wall_min_s": min(r["wall_s"] for r in rs), "wall_median_s": med([r["wall_s"] for r in rs]),
            "cpu_median_s": med([r["cpu_s"] for r in rs]), "rss_mb": max(r["rss_mb"] for r in rs),
            "frame_min_s": min(r["frame_s"] for r in rs) if rs[0]["frame_s"] is not None else None}
    for H in a.hierarchies:
        name = os.path.basename(H)
        if len(builds) > 1:
            files = [os.path.join(a.work, "%s_%s_%s.exr" % (name, b, a.size)) for b, _ in builds[:2]]
            same = subprocess.run(["cmp", "-s"] + files).returncode == 0
            res["%s image identical to base" % name] = same
    print("%-34s %10s %10s %10s %8s %10s" % ("command, size", "wall min", "wall med", "cpu med", "RSS MB",
                                              "frame min"))
    for k, v in res.items():
        if isinstance(v, dict):
            print("%-34s %10.3f %10.3f %10.3f %8.0f %10s" % (k, v["wall_min_s"], v["wall_median_s"], v["cpu_median_s"],
                                                         v["rss_mb"], "%.3f" % v["frame_min_s"]
                                                         if v["frame_min_s"] is not None else "-"))
        else:
            print(k, v)
    return res


def psnr(helper, a, b):
    out = subprocess.run([helper, "psnr", a, b], capture_output=True, text=True, check=True).stdout
    return json.loads(out)["psnr_db"]


def level_vertices(mlfe, h):
    """Vertices of T_k per level k: `mlfe info` lists the vertices each level adds, T_k has
    those of levels 0..k."""
    out = subprocess.run([mlfe, "info", h], capture_output=True, text=True, check=True).stdout
    rows, total = {}, 0
    for line in out.splitlines():
        m = re.match(r"\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)\s*$", line)
        if m:
            total += int(m.group(2))
            rows[int(m.group(1))] = total
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("volume")
    ap.add_argument("hierarchies", nargs="+")
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--base-build", default="")
    ap.add_argument("--work", default="/tmp/mlfe_render_e2e")
    ap.add_argument("--size", default="500x500")
    ap.add_argument("--tf", default="grey")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=0)
    ap.add_argument("--turntable", type=int, default=0)
    ap.add_argument("--no-vtk", action="store_true")
    ap.add_argument("--no-levels", action="store_true")
    ap.add_argument("--json", default="")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    mlfe = mlfe_binary(a.build)
    helper = os.path.join(a.build, "bench", "render_bench")
    builds = [("new", mlfe)]
    if a.base_build:
        builds.append(("base", mlfe_binary(a.base_build)))
    w, h = [int(x) for x in a.size.lower().split("x")]
    view = ["--azimuth", "0", "--elevation", "0", "--tf", a.tf]
    res = {"volume": a.volume, "size": a.size, "runs": {}}
    if a.turntable > 1:
        res["turntable"] = turntable(a, mlfe, helper, w, h)
        if a.json:
            with open(a.json, "w") as f:
                json.dump(res, f, indent=1)
        return
    if a.rounds > 0:
        res["interleaved"] = interleaved(a, builds, view)
        if a.json:
            with open(a.json, "w") as f:
                json.dump(res, f, indent=1)
        return

    def render(tag, binary, src, extra, size):
        out = os.path.join(a.work, tag + ".exr")
        r = run_mlfe(binary, ["render", src, "-o", out, "--size", size] + view + extra, a.repeat)
        r["exr"] = out
        return r

    ref_setup = render("ref_1x1", mlfe, a.volume, ["--reference"], "1x1")
    ref = render("ref", mlfe, a.volume, ["--reference"], a.size)
    res["reference"] = {"setup_s": ref_setup["wall_s"], "end_to_end_s": ref["wall_s"], "frame_s": ref["frame_s"]}
    print(json.dumps({"reference": res["reference"]}), flush=True)
    for H in a.hierarchies:
        name = os.path.basename(H)
        for bname, binary in builds:
            s = render("%s_%s_1x1" % (name, bname), binary, H, [], "1x1")
            e = render("%s_%s" % (name, bname), binary, H, [], a.size)
            row = {"setup_s": s["wall_s"], "end_to_end_s": e["wall_s"], "frame_s": e["frame_s"],
                   "psnr_db": psnr(helper, e["exr"], ref["exr"]), "stats": e["stats"]}
            res["runs"]["%s/%s" % (name, bname)] = row
            print(json.dumps({name + "/" + bname: row}), flush=True)
    if not a.no_levels:
        H = a.hierarchies[0]
        verts = level_vertices(mlfe, H)
        res["levels"] = []
        for k in sorted(verts):
            e = render("level%d" % k, mlfe, H, ["--level", str(k)], a.size)
            row = {"level": k, "vertices": verts[k], "end_to_end_s": e["wall_s"], "frame_s": e["frame_s"],
                   "psnr_db": psnr(helper, e["exr"], ref["exr"])}
            res["levels"].append(row)
            print(json.dumps(row), flush=True)
    if not a.no_vtk:
        env, xvfb = vtk_env()
        try:
            prefix = os.path.join(a.work, "vtk")
            setup, setup_path = vtk_setup(a, helper, 0, w, h, prefix)
            res["vtk"] = {}
            for label, dist in (("fixed_1voxel", 1.0 * min(setup["spacing"])),
                                ("fixed_half_voxel", 0.5 * min(setup["spacing"]))):
                res["vtk"][label] = vtk_render(a, env, setup_path, prefix, w, h, dist, prefix + "_" + label + ".png")
                print(json.dumps({label: res["vtk"][label]}), flush=True)
        finally:
            if xvfb:
                xvfb.terminate()
                xvfb.wait()
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
