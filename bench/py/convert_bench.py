#!/usr/bin/python3
"""convert_bench.py: `mlfe convert` at scan scale against the tools users choose between.

For every VOL:ISO case, in one run:
  * VTK vtkFlyingEdges3D on the full grid: the reference surface (distances are measured to it);
  * VTK vtkMarchingCubes + vtkQuadricDecimation to 10 % and 5 % of the MC triangles;
  * VTK flying edges + meshoptimizer meshopt_simplify (libmeshoptimizer-dev 0.18) to the same
    triangle counts (bench/iso_tools_bench meshopt);
  * VTK flying edges + meshoptimizer 1.2 meshopt_simplifyWithUpdate to 10 % of the MC triangles,
    positions only, no error limit (the count decides): build/bench-peers/meshopt_update, built
    by scripts/build_bench_peers.sh (the row is left out, with a note, when it is missing);
  * VTK flying edges + gltfpack 1.3 -si 0.1 (npm; OBJ in, .glb out);
  * OpenVDB tools::volumeToMesh with adaptivity 0.5 (bench/iso_tools_bench vdb);
  * `mlfe convert VOL --iso ISO -o X.glb` with its defaults, with each --simplify S of
    --tolerances and with each option set of --variants, at each thread count of
    --mlfe-threads; the whole command timed, peak RSS from /usr/bin/time. The same command is
    run again with -o X.ply for the distances (same geometry: outputs are deterministic).
Reported per row: triangles (% of MC), seconds, peak RSS (subprocesses only), symmetric mean
and Hausdorff distance to the flying-edges surface in voxels (iso_bench.distances), edges of
more than two triangles (non-manifold) and of one (boundary), Draco .glb bytes (mlfe's writer
and tolerance, normals included) and Draco .drc bytes of the positions alone; for mlfe rows
also the CLI's own .glb. Flying edges + meshoptimizer rows also give an end-to-end time (VTK's
reader on the volume + flying edges + the simplification + mlfe's .glb writer on the result),
comparable with the whole `mlfe convert` command.

usage: bench/py/convert_bench.py [--build DIR] [--peers DIR] [--work DIR] [--tolerances 0.3,0.6]
                              [--json OUT] [--no-quadric] [--variants "ARGS;ARGS"]
                              [--threads N] [--mlfe-threads 1,2] VOL:ISO [...]
Uses /usr/bin/python3 with python3-vtk9, python3-scipy (scripts/install_bench_deps.sh). --threads
(default 2) is given to VTK, the bench tools and mlfe; --mlfe-threads repeats every mlfe row at
each listed count instead.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import vtk

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import iso_bench as ib  # noqa: E402
from bench_paths import mlfe_binary  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def timed(cmd):
    """Runs cmd under /usr/bin/time; returns (stdout, seconds, peak RSS MiB)."""
    t0 = time.perf_counter()
    p = subprocess.run(["/usr/bin/time", "-f", "@@%M"] + cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                       text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({p.returncode}): {p.stderr[-2000:]}")
    rss = [l for l in p.stderr.splitlines() if l.startswith("@@")]
    return p.stdout, wall, (int(rss[-1][2:]) / 1024.0 if rss else float("nan"))


def physical_to_index(ply, out_ply, meta):
    """mlfe writes PLY in the physical frame (mm): back to voxel index coordinates."""
    poly = ib.read_ply(ply)
    pts = ib.ns.vtk_to_numpy(poly.GetPoints().GetData()).astype(np.float64)
    d = np.array(meta["direction"], dtype=np.float64).reshape(3, 3)
    o = np.array(meta["origin"], dtype=np.float64)
    s = np.array(meta["spacing"], dtype=np.float64)
    idx = np.linalg.solve(d, (pts - o).T).T / s
    poly.GetPoints().SetData(ib.ns.numpy_to_vtk(idx, deep=1))
    ib.write_ply(poly, out_ply)
    return poly


def gltfpack_row(W, fe, n_mc, t_fe):
    """Flying edges + gltfpack 1.3 (npm; meshoptimizer 1.x's simplifier) at 10 %: the surface is
    handed over as OBJ (as users do), `-si 0.1 -noq` (no quantization, so distances are the
    simplifier's), and read back from the .glb for the distances."""
    pts, tris = ib.tri_arrays(fe)
    obj = W("fe.obj")
    with open(obj, "w") as f:
        f.write("".join("v %.6f %.6f %.6f\n" % tuple(p) for p in pts))
        f.write("".join("f %d %d %d\n" % tuple(t + 1) for t in tris))
    glb = W("gltfpack.glb")
    _, wall, rss = timed(["gltfpack", "-i", obj, "-o", glb, "-si", "0.1", "-noq"])
    r = vtk.vtkGLTFReader()
    r.SetFileName(glb)
    r.Update()
    it = r.GetOutput().NewIterator()
    it.InitTraversal()
    app = vtk.vtkAppendPolyData()
    while not it.IsDoneWithTraversal():
        app.AddInputData(it.GetCurrentDataObject())
        it.GoToNextItem()
    app.Update()
    tri = vtk.vtkTriangleFilter()
    tri.SetInputData(app.GetOutput())
    tri.Update()
    ply = W("fe_gltfpack10.ply")
    ib.write_ply(tri.GetOutput(), ply)
    return dict(method="flying edges + gltfpack 1.3 -si 0.1", triangles=tri.GetOutput().GetNumberOfPolys(),
                seconds=t_fe + wall, detail=f"gltfpack {wall:.2f} (OBJ parse included)", peak_mb=rss, ply=ply,
                peer="gltfpack")


def meshopt_update_row(tool, W, n_mc, t_fe):
    """Flying edges + meshoptimizer 1.2 meshopt_simplifyWithUpdate to 10 % of the MC triangles."""
    ply = W("femu10.ply")
    out, _, rss = timed([tool, W("fe.ply"), str(max(1, n_mc // 10)), ply])
    j = json.loads(out.strip().splitlines()[-1])
    return dict(method="flying edges + meshoptimizer 1.2 simplifyWithUpdate 10%", triangles=j["triangles"],
                seconds=t_fe + j["simplify_seconds"],
                detail=f"simplifyWithUpdate {j['simplify_seconds']:.2f} (error limit none, reached "
                       f"{j['absolute_error']:.3g} vox)", peak_mb=rss, ply=ply, peer="femo")


def topology(poly):
    """(non-manifold edges, boundary edges) of a surface, vertices welded by position."""
    pts, tris = ib.tri_arrays(poly)
    _, ids = np.unique(pts, axis=0, return_inverse=True)
    t = ids.reshape(-1)[tris]
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return int((counts > 2).sum()), int((counts == 1).sum())


def glb_sizes(m2g, ply, spacing):
    j, _ = ib.run_json([m2g, ply, ply[:-4] + ".glb", "--scale", ",".join(str(x) for x in spacing), "--drc",
                        ply[:-4] + ".drc"])
    return j["bytes"], j["drc_positions_bytes"], j["write_seconds"]


def vtk_read_seconds(path, reps):
    """What reading the volume costs a VTK pipeline (NIfTI or NRRD reader), best of reps; nan otherwise."""
    low = path.lower()
    if low.endswith((".nii", ".nii.gz")):
        make = vtk.vtkNIFTIImageReader
    elif low.endswith((".nrrd", ".nhdr")):
        make = vtk.vtkNrrdReader
    else:
        return float("nan")
    best = float("inf")
    for _ in range(reps):
        r = make()
        r.SetFileName(path)
        t0 = time.perf_counter()
        r.Update()
        best = min(best, time.perf_counter() - t0)
    return best


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--peers", default=os.path.join(ROOT, "build", "bench-peers"),
                    help="where scripts/build_bench_peers.sh put meshopt_update")
    ap.add_argument("--threads", type=int, default=ib.THREADS)
    ap.add_argument("--mlfe-threads", default="", help="run every mlfe row at each of these thread counts (1,2)")
    ap.add_argument("--work", default="/tmp/mlfe_convert_bench")
    ap.add_argument("--tolerances", default="0.3,0.6", help="extra mlfe runs with --simplify S (voxels)")
    ap.add_argument("--variants", default="",
                    help="extra mlfe runs with these options, ';'-separated (e.g. '--simplifier bounded;--surface hierarchy')")
    ap.add_argument("--samples", type=int, default=60000)
    ap.add_argument("--json", default=None)
    ap.add_argument("--no-gltfpack", action="store_true", help="skip flying edges + gltfpack (npm gltfpack 1.3)")
    ap.add_argument("--no-quadric", action="store_true", help="skip MC + quadric decimation (slow on big volumes)")
    ap.add_argument("cases", nargs="+", help="VOL:ISO")
    args = ap.parse_args()
    ib.THREADS = args.threads
    mlfe_threads = [int(x) for x in args.mlfe_threads.split(",") if x] or [args.threads]
    meshopt_update = os.path.join(args.peers, "meshopt_update")
    if not os.path.exists(meshopt_update):
        ib.log(f"no {meshopt_update} (scripts/build_bench_peers.sh): no meshoptimizer 1.2 row")
    tools = os.path.join(args.build, "bench", "iso_tools_bench")
    m2g = os.path.join(args.build, "bench", "mesh_to_glb_bench")
    mlfe = mlfe_binary(args.build)
    os.makedirs(args.work, exist_ok=True)
    vtk.vtkSMPTools.Initialize(ib.THREADS)
    all_rows = []
    for case in args.cases:
        path, iso = case.rsplit(":", 1)
        iso = float(iso)
        name, img, meta = ib.load_volume(tools, path, args.work)
        voxels = int(np.prod(meta["dims"]))
        W = lambda s: os.path.join(args.work, f"{name}_{iso:g}_{s}")
        rng = np.random.default_rng(1)
        ib.log(f"== {name} iso {iso:g} ({voxels} voxels)")
        reps = 3 if voxels < 20e6 else 1
        t_read = vtk_read_seconds(path, reps)
        t_fe, fe = ib.best_of(reps, lambda: ib.flying_edges(img, iso))
        t_mc, mc = ib.best_of(reps, lambda: ib.marching_cubes(img, iso))
        n_mc = mc.GetNumberOfPolys()
        ib.write_ply(fe, W("fe.ply"))
        rows = [dict(method="VTK flying edges (reference)", triangles=fe.GetNumberOfPolys(), seconds=t_fe,
                     ply=W("fe.ply")),
                dict(method="VTK marching cubes", triangles=n_mc, seconds=t_mc, ply=None)]
        for pct in (10, 5):
            tgt = max(1, n_mc * pct // 100)
            if not args.no_quadric:
                t_d, dec = ib.best_of(1, lambda: ib.quadric(mc, tgt))
                ply = W(f"mcqd{pct}.ply")
                ib.write_ply(dec, ply)
                rows.append(dict(method=f"MC + quadric decimation to {pct}%", triangles=dec.GetNumberOfPolys(),
                                 seconds=t_mc + t_d, detail=f"decimation {t_d:.2f}", ply=ply, peer="mcqd"))
            ply = W(f"femo{pct}.ply")
            out, wall, rss = timed([tools, "--threads", str(ib.THREADS), "meshopt", W("fe.ply"), str(tgt), ply])
            j = json.loads(out.strip().splitlines()[-1])
            rows.append(dict(method=f"flying edges + meshopt_simplify to {pct}%", triangles=j["triangles"],
                             seconds=t_fe + j["simplify_seconds"], detail=f"meshopt {j['simplify_seconds']:.2f}",
                             peak_mb=rss, ply=ply, peer="femo"))
        if os.path.exists(meshopt_update):
            rows.append(meshopt_update_row(meshopt_update, W, n_mc, t_fe))
        if shutil.which("gltfpack") and not args.no_gltfpack:
            rows.append(gltfpack_row(W, fe, n_mc, t_fe))
        # The surface the lattice's finest level gives (Kuhn marching tetrahedra on every voxel
        # cube, unsimplified): what an asset extracted at the samples starts from.
        ply = W("kuhn.ply")
        out, wall, rss = timed([tools, "kuhn", path, f"{iso:g}", ply])
        j = json.loads(out.strip().splitlines()[-1])
        rows.append(dict(method="Kuhn marching tetrahedra, every voxel (finest level)", triangles=j["triangles"],
                         seconds=j["seconds"], detail="unsimplified", peak_mb=rss, ply=ply))
        ply = W("vdb.ply")
        out, wall, rss = timed([tools, "--threads", str(ib.THREADS), "vdb", path, f"{iso:g}", "0.5", ply])
        j = json.loads(out.strip().splitlines()[-1])
        rows.append(dict(method="OpenVDB volumeToMesh adaptivity 0.5", triangles=j["triangles"],
                         seconds=j["mesh_seconds"], detail=f"+ grid {j['grid_seconds']:.2f}", peak_mb=rss, ply=ply))
        runs = [("default", "mlfe convert (defaults)", [])]
        runs += [(f"s{float(x):g}", f"mlfe convert --simplify {float(x):g}", ["--simplify", f"{float(x):g}"])
                 for x in args.tolerances.split(",") if x]
        runs += [(f"v{i}", f"mlfe convert {v.strip()}", v.split()) for i, v in enumerate(args.variants.split(";"))
                 if v.strip()]
        if len(mlfe_threads) > 1:
            runs = [(f"{key}_t{n}", f"{label} (threads {n})", extra, n) for key, label, extra in runs
                    for n in mlfe_threads]
        else:
            runs = [(key, label, extra, mlfe_threads[0]) for key, label, extra in runs]
        for key, label, extra, threads in runs:
            glb, rep = W(f"mlfe_{key}.glb"), W(f"mlfe_{key}.json")
            cmd = [mlfe, "--threads", str(threads), "convert", path, "--iso", f"{iso:g}"] + extra
            ib.log("  ", " ".join(cmd))
            _, wall, rss = timed(cmd + ["-o", glb, "--report", rep, "--quiet"])
            report = json.load(open(rep))
            subprocess.run(cmd + ["-o", W(f"mlfe_{key}_mm.ply"), "--quiet"], check=True, stdout=subprocess.DEVNULL)
            physical_to_index(W(f"mlfe_{key}_mm.ply"), W(f"mlfe_{key}.ply"), meta)
            # A volume read in bricks builds no hierarchy (its report has no build figures).
            detail = (f"read in bricks, asset {report['asset']['seconds']:.2f}" if "read_in_windows" in report else
                      f"build {report['seconds']:.2f}, asset {report['asset']['seconds']:.2f}; "
                      f"{report['vertices']} vertices, {report['elements']} leaves")
            rows.append(dict(method=label, triangles=report["asset"]["triangles"], seconds=wall, detail=detail,
                             peak_mb=rss, ply=W(f"mlfe_{key}.ply"), cli_glb=os.path.getsize(glb),
                             leaves=report.get("elements", 0), report=report))
        ref = ib.Surface(fe, rng, args.samples)
        for r in rows:
            if r["ply"] is None:
                r["mean_vox"] = r["hausdorff_vox"] = float("nan")
                r["glb"] = r["drc"] = 0
                continue
            ib.log("   distances:", r["method"])
            poly = fe if r["ply"] == W("fe.ply") else ib.read_ply(r["ply"])
            r["mean_vox"], r["hausdorff_vox"] = (0.0, 0.0) if poly is fe else ib.distances(ref, poly, rng, args.samples)
            r["nm_edges"], r["boundary_edges"] = topology(poly)
            r["glb"], r["drc"], r["glb_write_seconds"] = glb_sizes(m2g, r["ply"], meta["spacing"])
            # A user's flying edges + meshoptimizer pipeline also reads the volume and writes
            # the asset: its end-to-end time is comparable with mlfe convert's (the command).
            if r.get("peer") == "femo":
                r["end_to_end_seconds"] = t_read + r["seconds"] + r["glb_write_seconds"]
                r["detail"] += f"; end to end {r['end_to_end_seconds']:.2f} (VTK read {t_read:.2f}, .glb write " \
                               f"{r['glb_write_seconds']:.2f})"
        for r in rows:
            r.pop("report", None)
            r.update(volume=name, iso=iso, voxels=voxels, mc_triangles=n_mc)
        all_rows.extend(rows)
        print_table(name, iso, meta, voxels, rows)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(all_rows, f, indent=1)


def print_table(name, iso, meta, voxels, rows):
    n_mc = rows[1]["triangles"]
    print(f"\n### {name}, iso {iso:g} ({'x'.join(map(str, meta['dims']))} = {voxels / 1e6:.1f} M voxels, spacing "
          f"{', '.join(f'{s:.4g}' for s in meta['spacing'])} mm)\n")
    print("| method | triangles | % of MC | seconds | peak MiB | mean vox | Hausdorff vox | non-manifold / boundary edges | .glb B (normals) | .drc B (positions) | notes |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for r in rows:
        peak = f"{r['peak_mb']:.0f}" if "peak_mb" in r else "in-process"
        glb = f"{r['glb']}" + (f" (CLI {r['cli_glb']})" if "cli_glb" in r else "")
        print(f"| {r['method']} | {r['triangles']} | {100.0 * r['triangles'] / n_mc:.1f} | {r['seconds']:.2f} | {peak} | "
              f"{r['mean_vox']:.3f} | {r['hausdorff_vox']:.2f} | {r.get('nm_edges', '')} / {r.get('boundary_edges', '')} | {glb} | {r['drc']} | {r.get('detail', '')} |")
    by = {r["method"]: r for r in rows}
    mcqd = by.get("MC + quadric decimation to 10%")
    femo = by.get("flying edges + meshopt_simplify to 10%")
    femu = by.get("flying edges + meshoptimizer 1.2 simplifyWithUpdate 10%")
    for r in rows:
        if not r["method"].startswith("mlfe"):
            continue
        line = f"- {r['method']}: {100.0 * r['triangles'] / n_mc:.1f}% of MC, mean {r['mean_vox']:.3f}, " \
               f"Hausdorff {r['hausdorff_vox']:.2f}, {r['seconds']:.2f} s, {r['peak_mb']:.0f} MiB, "
        line += f"{r['peak_mb'] * 1048576 / r['leaves']:.0f} B/leaf, " if r["leaves"] > 1000 else "no hierarchy, "
        line += f"{r['peak_mb'] * 1048576 / voxels:.1f} B/voxel"
        if mcqd:
            line += f"; time / (MC + QD 10%) = {r['seconds'] / mcqd['seconds']:.2f}"
        if femo:
            line += f"; time / (FE + meshopt 10%) = {r['seconds'] / femo['seconds']:.2f}"
            if "end_to_end_seconds" in femo:
                line += f" (end to end, read and .glb write included: {r['seconds'] / femo['end_to_end_seconds']:.2f})"
        if femu:
            line += f"; time / (FE + meshopt 1.2 update 10%) = {r['seconds'] / femu['seconds']:.2f} (end to end " \
                    f"{r['seconds'] / femu['end_to_end_seconds']:.2f})"
        print(line)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
