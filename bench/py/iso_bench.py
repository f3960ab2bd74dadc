#!/usr/bin/python3
"""iso_bench.py: iso-surfaces of mlfe hierarchies against VTK and OpenVDB on the full grid.

For every volume and iso-value it extracts:
  * VTK vtkFlyingEdges3D on the full voxel grid (the reference surface),
  * VTK vtkMarchingCubes on the full voxel grid,
  * marching cubes + vtkQuadricDecimation to 10 % and 2 % of the MC triangles, and to the
    triangle count of every mlfe run (for the time and size comparisons),
  * OpenVDB tools::volumeToMesh with adaptivity 0 and 1 (bench/cpp/iso_tools_bench.cpp),
  * mlfe: `mlfe convert VOL --iso v --max-vertices N -o X.glb --hierarchy X.mlfeh` (whole
    command timed), then the extraction alone from X.mlfeh (iso_tools_bench extract).
and reports triangles, time, the symmetric mean and Hausdorff distance to the flying-edges
surface in voxels (area-uniform samples plus all vertices of each surface, exact
point-to-triangle distances to the candidate triangles found by a scipy KD-tree over dense
samples of the other surface), and the Draco .glb bytes (every mesh
written by bench/cpp/mesh_to_glb_bench.cpp with mlfe's default tolerance, voxel/10 in mm).

All geometry is in voxel index coordinates (x = i, y = j, z = k). Uses the Debian python3
(python3-vtk9, python3-numpy; scripts/install_bench_deps.sh). Threads: VTK SMP (TBB) and mlfe
are limited to 2.

usage: bench/py/iso_bench.py [--build DIR] [--work DIR] [--quick] [VOL:iso1,iso2:budget1,budget2 ...]
"""
import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np
import vtk
from scipy.spatial import cKDTree
from vtk.util import numpy_support as ns
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_paths import mlfe_binary  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DATA = os.path.normpath(os.path.join(ROOT, "..", "shared", "data"))
THREADS = 2


def log(*a):
    print(*a, file=sys.stderr, flush=True)


def run_json(cmd):
    t0 = time.perf_counter()
    p = subprocess.run(cmd, check=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    lines = [l for l in p.stdout.splitlines() if l.startswith("{")]
    return (json.loads(lines[-1]) if lines else {}), wall


def load_volume(tools, path, work):
    name = os.path.basename(path).split(".")[0]
    raw = os.path.join(work, name + ".raw")
    meta, _ = run_json([tools, "dump", path, raw])
    nx, ny, nz = meta["dims"]
    a = np.fromfile(raw, dtype=np.float32)
    img = vtk.vtkImageData()
    img.SetDimensions(nx, ny, nz)
    img.SetSpacing(1, 1, 1)
    img.SetOrigin(0, 0, 0)
    arr = ns.numpy_to_vtk(a, deep=1)
    arr.SetName("f")
    img.GetPointData().SetScalars(arr)
    return name, img, meta


def best_of(n, fn):
    best, out = 1e300, None
    for _ in range(n):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def vtk_contour(filter_class, img, iso):
    """One iso-surface with normals from a VTK contour filter (flying edges or marching cubes)."""
    f = filter_class()
    f.SetInputData(img)
    f.SetValue(0, iso)
    f.ComputeNormalsOn()
    f.ComputeGradientsOff()
    f.ComputeScalarsOff()
    f.Update()
    return f.GetOutput()


def flying_edges(img, iso):
    return vtk_contour(vtk.vtkFlyingEdges3D, img, iso)


def marching_cubes(img, iso):
    return vtk_contour(vtk.vtkMarchingCubes, img, iso)


def quadric(poly, target_tris):
    n = poly.GetNumberOfPolys()
    d = vtk.vtkQuadricDecimation()
    d.SetInputData(poly)
    d.SetTargetReduction(max(0.0, 1.0 - float(target_tris) / n))
    d.VolumePreservationOff()
    d.Update()
    return d.GetOutput()


def read_ply(path):
    r = vtk.vtkPLYReader()
    r.SetFileName(path)
    r.Update()
    return r.GetOutput()


def write_ply(poly, path):
    w = vtk.vtkPLYWriter()
    w.SetFileName(path)
    w.SetInputData(poly)
    w.SetFileTypeToBinary()
    w.Write()


def tri_arrays(poly):
    pts = ns.vtk_to_numpy(poly.GetPoints().GetData()).astype(np.float64)
    cells = poly.GetPolys()
    conn = ns.vtk_to_numpy(cells.GetConnectivityArray()).astype(np.int64)
    offs = ns.vtk_to_numpy(cells.GetOffsetsArray()).astype(np.int64)
    if not np.all(np.diff(offs) == 3):
        raise RuntimeError("non-triangle cells")
    return pts, conn.reshape(-1, 3)


def closest_on_triangles(p, a, b, c):
    """Vectorized closest points on triangles (a, b, c) to points p (Ericson, Real-Time
    Collision Detection, 5.1.5); all arrays (n, 3). Returns the distances."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = np.where(denom != 0, vb / denom, 0.0)
        w = np.where(denom != 0, vc / denom, 0.0)
        q = a + ab * v[:, None] + ac * w[:, None]  # interior
        # edge bc
        m = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        q = np.where(m[:, None], b + (c - b) * np.nan_to_num(t)[:, None], q)
        # edge ac
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        t = d2 / (d2 - d6)
        q = np.where(m[:, None], a + ac * np.nan_to_num(t)[:, None], q)
        # edge ab
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        t = d1 / (d1 - d3)
        q = np.where(m[:, None], a + ab * np.nan_to_num(t)[:, None], q)
    q = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, q)
    q = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, q)
    q = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, q)
    return np.linalg.norm(p - q, axis=1)


class Surface:
    """A triangle mesh prepared for point-to-surface distance queries: a KD-tree over dense
    samples (vertices, centroids and area samples, each tagged with its triangle); a query
    computes the exact distance to the triangles of the K nearest samples."""
    K = 24

    def __init__(self, poly, rng, nsamples, density=4.0):
        self.pts, self.tris = tri_arrays(poly)
        a, b, c = (self.pts[self.tris[:, i]] for i in range(3))
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        self.area = area
        nt = len(self.tris)
        # Dense samples for the candidate search (density per voxel^2, at least the centroid).
        ndense = int(min(6e6, density * area.sum()))
        pick = rng.choice(nt, size=ndense, p=area / area.sum())
        dense = self._sample(a, b, c, pick, rng)
        cent = (a + b + c) / 3.0
        # Each vertex tagged with one incident triangle.
        vt = np.zeros(len(self.pts), dtype=np.int64)
        vt[self.tris.ravel()] = np.repeat(np.arange(nt), 3)
        used = np.zeros(len(self.pts), dtype=bool)
        used[self.tris.ravel()] = True
        self.cand_pts = np.concatenate([dense, cent, self.pts[used]])
        self.cand_tri = np.concatenate([pick, np.arange(nt), vt[used]])
        self.tree = cKDTree(self.cand_pts)
        # Area-uniform samples of this surface (for distances from it to others).
        pick = rng.choice(nt, size=nsamples, p=area / area.sum())
        self.samples = self._sample(a, b, c, pick, rng)
        self.verts = self.pts[used]

    @staticmethod
    def _sample(a, b, c, pick, rng):
        n = len(pick)
        r1, r2 = rng.random(n), rng.random(n)
        s = np.sqrt(r1)
        u, v, w = 1 - s, s * (1 - r2), s * r2
        return u[:, None] * a[pick] + v[:, None] * b[pick] + w[:, None] * c[pick]

    def distance(self, p):
        out = np.empty(len(p))
        for lo in range(0, len(p), 100000):
            q = p[lo:lo + 100000]
            _, idx = self.tree.query(q, k=self.K, workers=THREADS)
            tri = self.cand_tri[idx]  # (n, K)
            n = len(q)
            qq = np.repeat(q, self.K, axis=0)
            t = self.tris[tri.ravel()]
            d = closest_on_triangles(qq, self.pts[t[:, 0]], self.pts[t[:, 1]], self.pts[t[:, 2]])
            out[lo:lo + n] = d.reshape(n, self.K).min(axis=1)
        return out


def distances(ref, poly, rng, nsamples):
    """Symmetric mean (average of the two one-sided means over area-uniform samples) and
    Hausdorff (max over area samples and all vertices, both directions), in voxels."""
    if poly.GetNumberOfPolys() == 0:
        return float("nan"), float("nan")
    other = Surface(poly, rng, nsamples)
    d_ab = ref.distance(other.samples)
    d_ab_v = ref.distance(other.verts)
    d_ba = other.distance(ref.samples)
    d_ba_v = other.distance(ref.verts)
    mean = 0.5 * (d_ab.mean() + d_ba.mean())
    haus = max(d_ab.max(), d_ab_v.max(), d_ba.max(), d_ba_v.max())
    return float(mean), float(haus)


def glb_bytes(m2g, ply, glb, spacing):
    j, _ = run_json([m2g, ply, glb, "--scale", ",".join(str(s) for s in spacing)])
    return j["bytes"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build-bench"))
    ap.add_argument("--work", default="/tmp/mlfe_iso_bench")
    ap.add_argument("--samples", type=int, default=60000, help="area samples per surface")
    ap.add_argument("--json", default=None, help="also write all rows as JSON here")
    ap.add_argument("--simplify", default="0",
                    help="comma-separated `mlfe convert --simplify` tolerances in voxels to run per budget (0: none)")
    ap.add_argument("--snap", type=float, default=1.0,
                    help="`mlfe convert --snap` in voxels (the CLI's default 1; 0: the approximation's own surface)")
    ap.add_argument("--placement", default="optimal", choices=["input", "optimal"],
                    help="mlfe --simplify vertex placement (passed to convert and to the extraction)")
    ap.add_argument("--mlfe-args", default="", help="extra arguments for every mlfe convert (space separated)")
    ap.add_argument("cases", nargs="*", help="VOL:iso1,iso2:maxv1,maxv2")
    args = ap.parse_args()
    cases = args.cases or [
        os.path.join(DATA, "ct_skull_64.nrrd") + ":1.5,3.0:8000,30000",
        os.path.join(DATA, "mri_colin27_brain.nii.gz") + ":60,100:100000,400000",
    ]
    tools = os.path.join(args.build, "bench", "iso_tools_bench")
    m2g = os.path.join(args.build, "bench", "mesh_to_glb_bench")
    mlfe = mlfe_binary(args.build)
    os.makedirs(args.work, exist_ok=True)
    vtk.vtkSMPTools.Initialize(THREADS)
    log("VTK", vtk.vtkVersion.GetVTKVersion(), "SMP backend", vtk.vtkSMPTools.GetBackend(),
        "threads", vtk.vtkSMPTools.GetEstimatedNumberOfThreads())
    all_rows = []
    for case in cases:
        path, isos, budgets = case.split(":")
        isos = [float(x) for x in isos.split(",")]
        budgets = [int(x) for x in budgets.split(",")]
        name, img, meta = load_volume(tools, path, args.work)
        spacing = meta["spacing"]
        for iso in isos:
            rng = np.random.default_rng(1)
            tag = f"{name}_{iso:g}"
            W = lambda s: os.path.join(args.work, f"{tag}_{s}")
            rows = []
            log(f"== {name} iso {iso:g}")
            t_fe, fe = best_of(3, lambda: flying_edges(img, iso))
            t_mc, mc = best_of(3, lambda: marching_cubes(img, iso))
            n_mc = mc.GetNumberOfPolys()
            ref = Surface(fe, rng, args.samples)
            write_ply(fe, W("fe.ply"))
            write_ply(mc, W("mc.ply"))
            rows.append(dict(method="VTK flying edges (full grid)", triangles=fe.GetNumberOfPolys(), seconds=t_fe,
                             ply=W("fe.ply")))
            rows.append(dict(method="VTK marching cubes (full grid)", triangles=n_mc, seconds=t_mc, ply=W("mc.ply")))

            # mlfe first: its triangle counts are decimation targets.
            mlfe_rows = []
            extra = args.mlfe_args.split()
            for mv in budgets:
                for simp in [float(x) for x in args.simplify.split(",")]:
                    key = f"{mv}" + (f"s{simp:g}" if simp > 0 else "")
                    glb, hier, rep = W(f"mlfe{key}.glb"), W(f"mlfe{key}.mlfeh"), W(f"mlfe{key}.json")
                    cmd = [mlfe, "--threads", str(THREADS), "convert", path, "--iso", f"{iso:g}"]
                    if mv > 0:
                        cmd += ["--max-vertices", str(mv)]
                    if simp > 0:
                        cmd += ["--simplify", f"{simp:g}"]
                    cmd += ["--snap", f"{args.snap:g}"]
                    if simp > 0:
                        cmd += ["--placement", args.placement]
                    cmd += extra + ["-o", glb, "--hierarchy", hier, "--report", rep, "--quiet"]
                    log("  ", " ".join(cmd))
                    t0 = time.perf_counter()
                    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
                    t_conv = time.perf_counter() - t0
                    report = json.load(open(rep))
                    ecmd = [tools, "--threads", str(THREADS), "extract", hier, f"{iso:g}", W(f"mlfe{key}.ply")]
                    ecmd += [f"{simp:g}", path, f"{args.snap:g}"]
                    if args.placement != "input":
                        ecmd += [args.placement]
                    ex, _ = run_json(ecmd)
                    label = "mlfe convert" + (f" --max-vertices {mv}" if mv > 0 else "") + \
                        (f" --simplify {simp:g}" if simp > 0 else "") + f" --snap {args.snap:g}" + \
                        (f" --placement {args.placement}" if simp > 0 else "") + \
                        (" " + args.mlfe_args if extra else "")
                    r = dict(method=label, triangles=ex["triangles"], seconds=t_conv,
                             extract_seconds=ex["extract_seconds"], extract_setup_seconds=ex["setup_seconds"],
                             simplify_seconds=ex.get("simplify_seconds", 0.0),
                             extracted_triangles=ex.get("extracted_triangles", ex["triangles"]),
                             build_seconds=report["seconds"], hierarchy_vertices=report["vertices"],
                             psnr_db=report["psnr_db"], peak_rss_mb=report["peak_rss_mb"],
                             cli_glb_bytes=os.path.getsize(glb), ply=W(f"mlfe{key}.ply"), budget=key,
                             cli_triangles=report["asset"]["triangles"])
                    mlfe_rows.append(r)

            targets = [("10%", max(1, n_mc // 10)), ("2%", max(1, n_mc // 50))]
            for r in mlfe_rows:
                targets.append((f"= mlfe {r['budget']}", r["triangles"]))
            for label, tgt in targets:
                t_d, dec = best_of(1, lambda: quadric(mc, tgt))
                ply = W(f"mcqd_{tgt}.ply")
                write_ply(dec, ply)
                rows.append(dict(method=f"MC + quadric decimation to {label} ({tgt})", triangles=dec.GetNumberOfPolys(),
                                 seconds=t_mc + t_d, decimation_seconds=t_d, ply=ply, target=tgt))
            for ad in (0.0, 1.0):
                ply = W(f"vdb{ad:g}.ply")
                j, _ = run_json([tools, "--threads", str(THREADS), "vdb", path, f"{iso:g}", f"{ad:g}", ply])
                rows.append(dict(method=f"OpenVDB volumeToMesh adaptivity {ad:g}", triangles=j["triangles"],
                                 seconds=j["mesh_seconds"], grid_seconds=j["grid_seconds"], ply=ply))
            rows.extend(mlfe_rows)

            for r in rows:
                log("   distances:", r["method"])
                poly = fe if r["ply"] == W("fe.ply") else read_ply(r["ply"])
                r["mean_vox"], r["hausdorff_vox"] = distances(ref, poly, rng, args.samples)
                r["glb_bytes"] = glb_bytes(m2g, r["ply"], r["ply"][:-4] + ".glb", spacing)
                r.update(volume=name, iso=iso, mc_triangles=n_mc, fe_seconds=t_fe)
            all_rows.extend(rows)
            print_table(name, iso, meta, rows)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(all_rows, f, indent=1)


def print_table(name, iso, meta, rows):
    n_mc = rows[1]["triangles"]
    t_fe = rows[0]["seconds"]
    print(f"\n### {name}, iso {iso:g} (dims {'x'.join(map(str, meta['dims']))}, spacing "
          f"{', '.join(f'{s:.4g}' for s in meta['spacing'])} mm)\n")
    print("| method | triangles | % of MC | time s | mean dist vox | Hausdorff vox | Draco .glb bytes |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        extra = ""
        if "extract_seconds" in r:
            extra = f" (build {r['build_seconds']:.2f}, extract {r['extract_seconds']:.3f}"
            if r.get("simplify_seconds", 0) > 0:
                extra += f", simplify {r['simplify_seconds']:.2f} from {r['extracted_triangles']} triangles"
            extra += ")"
        elif "decimation_seconds" in r:
            extra = f" (decimation {r['decimation_seconds']:.2f})"
        glb = f"{r['glb_bytes']}"
        if "cli_glb_bytes" in r:
            glb += f" (CLI .glb {r['cli_glb_bytes']})"
        print(f"| {r['method']} | {r['triangles']} | {100.0 * r['triangles'] / n_mc:.1f} | {r['seconds']:.3f}{extra} | "
              f"{r['mean_vox']:.4f} | {r['hausdorff_vox']:.3f} | {glb} |")
    print()
    for r in rows:
        if "extract_seconds" not in r:
            continue
        mv = r["budget"]
        same = [x for x in rows if x.get("target") == r["triangles"] and "decimation_seconds" in x]
        ok = lambda b: "MET" if b else "NOT MET"
        print(f"- mlfe {mv}: extraction from the hierarchy {r['extract_seconds']:.4f} s vs flying edges {t_fe:.4f} s: "
              f"{ok(r['extract_seconds'] <= t_fe)} ({r['extract_seconds'] / t_fe:.2f}x)")
        frac = r["triangles"] / n_mc
        if frac <= 0.10:
            print(f"- mlfe {mv}: {100 * frac:.1f}% of MC triangles; mean {r['mean_vox']:.4f} vox (<= 0.1: "
                  f"{ok(r['mean_vox'] <= 0.1)}), Hausdorff {r['hausdorff_vox']:.3f} vox (<= 2: {ok(r['hausdorff_vox'] <= 2)})")
        else:
            print(f"- mlfe {mv}: {100 * frac:.1f}% of MC triangles (> 10%: accuracy target not applicable at this "
                  f"budget); mean {r['mean_vox']:.4f} vox, Hausdorff {r['hausdorff_vox']:.3f} vox")
        if same:
            s = same[0]
            print(f"- mlfe {mv}: whole convert {r['seconds']:.2f} s vs MC + decimation to {s['triangles']} triangles "
                  f"{s['seconds']:.2f} s: {ok(r['seconds'] <= s['seconds'] / 3)} (ratio {r['seconds'] / s['seconds']:.2f}, "
                  f"target <= 0.33)")
            print(f"- mlfe {mv}: Draco .glb {r['glb_bytes']} B (CLI {r['cli_glb_bytes']} B) vs decimated MC "
                  f"{s['glb_bytes']} B: {ok(r['cli_glb_bytes'] <= s['glb_bytes'])} "
                  f"(ratio {r['cli_glb_bytes'] / s['glb_bytes']:.2f})")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
