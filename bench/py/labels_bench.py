#!/usr/bin/python3
"""Label maps (issue #24): `mlfe convert --labels` against the Slicer-like VTK pipeline.

Peers, in one run on the same files:
  - mlfe: `mlfe convert VOL --labels -o out.glb --report r.json`, timed end to end (read, label
    checks, extraction, smoothing, simplification, Draco .glb), peak RSS from `/usr/bin/time -f %M`.
  - VTK 9.1 (python3-vtk9), what 3D Slicer does to make closed surfaces: per label
    vtkDiscreteFlyingEdges3D, vtkWindowedSincPolyDataFilter (20 iterations, pass band 0.1,
    non-manifold smoothing, normalized coordinates, as Slicer), vtkQuadricDecimation to 10 %
    (target reduction 0.9). Timed from reading the volume to the last decimated label, in its
    own process (peak RSS of that process: VmHWM of its own address space). Its meshes are written to PLY after the clock stops
    and packed into a Draco .glb at mlfe's tolerance by label_distance_bench, for the bytes.
  - Surface Nets (issue #40 item 4): VTK 9.3's vtkSurfaceNets3D, one pass over all labels, 2
    threads (vtkSMPTools), its defaults, with its built-in constrained smoothing on and off (rows
    sn_smooth, sn_raw). VTK 9.1 has no such filter, so it runs as an out-of-repository tool
    (`--surface-nets PATH`, default <build>/bench-peers/surface_nets_labels; the filter's source
    is built against Debian's VTK 9.1 outside this repository; without the tool the rows are
    skipped and the skip is printed). Interface: `TOOL VOLUME DIR PREFIX --smoothing on|off
    --threads 2` times reading + label list + filter in its own clock (peak: its VmHWM then),
    prints one JSON line (seconds, peak_rss_mb, triangles of the shared output, ...) and writes
    each label's triangles (both sides of the shared mesh, oriented outward for that label) to
    DIR/PREFIX_<label>.ply after the clock stops. Median of 3 runs per mode.
  - The reference per label: its voxel-boundary surface, vtkDiscreteFlyingEdges3D unsmoothed
    (the first stage of the VTK pipeline, written to PLY outside the timed part).
Peak RSS: not getrusage's ru_maxrss of the process itself, nor of a child of this script: Linux
carries the high-water mark over fork and exec, so a child of this script (which holds the parcel
volume and the distance arrays) reports at least this script's own peak (the earlier run recorded
352.5 MB for both peers). /usr/bin/time forks from its own small image, and VmHWM belongs to the
address space made by exec, so both measure the peer alone.

Distances per label (label_distance_bench, core/surface/mesh_distance.h): symmetric Hausdorff and the
larger one-sided mean, in voxels, vertices + 20 000 area samples per mesh; the same tool counts each
label mesh's topology (closed: no boundary edge; manifold: no edge in three or more triangles, every
vertex one fan) for every method. Triangles: each method's per-label meshes summed (an interface
counted once per side, as mlfe's .glb and the per-label VTK pipeline hold it); Surface Nets' shared
output (each interface once) is given beside it.

The >= 100-label volume: the colin27 brain (181 x 217 x 181, 1 mm) cut into 60 Voronoi parcels
(seeds drawn with a fixed generator inside the brain mask) and two intensity classes (below and
above the brain's median), 120 labels; written as a uint16 NRRD. Issue #40's other two (--volumes
atlas2mm,atlas05mm): 192 labels at 2 mm (91 x 109 x 91) and 709 at 0.5 mm, int16 (168 x 206 x 128,
124 of them small balls); make_atlas_2mm and make_atlas_05mm say how.

  /usr/bin/python3 bench/py/labels_bench.py --build build --out /tmp/labels_bench
  /usr/bin/python3 bench/py/labels_bench.py --build build --volumes parcels,atlas2mm,atlas05mm
  /usr/bin/python3 bench/py/labels_bench.py --build build --timing-rounds 5 --base-build ../base/build
  /usr/bin/python3 bench/py/labels_bench.py --build build --volumes parcels --surface-nets /path/to/surface_nets_labels
"""
import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_paths import mlfe_binary  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.path.join(HERE, "..", "..", "..", "shared", "data")


def colin27():
    """The colin27 brain as a (k, j, i) float array."""
    from vtkmodules.vtkIOImage import vtkNIFTIImageReader
    from vtkmodules.util.numpy_support import vtk_to_numpy
    r = vtkNIFTIImageReader()
    r.SetFileName(os.path.join(SHARED, "mri_colin27_brain.nii.gz"))
    r.Update()
    img = r.GetOutput()
    nx, ny, nz = img.GetDimensions()
    return vtk_to_numpy(img.GetPointData().GetScalars()).reshape(nz, ny, nx).astype(np.float32)


def parcellate(a, parcels, seed, sigma=0):
    """2 intensity classes (below and above the brain's median, of the image blurred by a Gaussian
    of `sigma` voxels when sigma > 0, so the classes have smooth boundaries like an atlas's) x
    `parcels` Voronoi cells (seeds drawn with a fixed generator inside the brain mask a > 0),
    labels 1 .. 2 * parcels."""
    mask = a > 0
    if sigma > 0:
        from scipy.ndimage import gaussian_filter
        a = gaussian_filter(a, sigma)
    idx = np.argwhere(mask)  # (k, j, i)
    rng = np.random.default_rng(seed)
    seeds = idx[rng.choice(len(idx), parcels, replace=False)].astype(np.float32)
    cell = np.empty(len(idx), np.int32)
    for s in range(0, len(idx), 100000):
        p = idx[s:s + 100000].astype(np.float32)
        d = ((p[:, None, :] - seeds[None, :, :]) ** 2).sum(axis=2)
        cell[s:s + 100000] = d.argmin(axis=1)
    bright = a[mask] > np.median(a[mask])
    labels = np.zeros(a.shape, np.int32)
    labels[mask] = 1 + cell + parcels * bright
    return labels


def write_nrrd(out_path, labels, spacing, dtype):
    nz, ny, nx = labels.shape
    header = ("NRRD0004\ntype: {}\ndimension: 3\nsizes: {} {} {}\nspace: RAS\n"
              "space directions: ({s},0,0) (0,{s},0) (0,0,{s})\nspace origin: (0,0,0)\nendian: little\n"
              "encoding: raw\n\n").format("uint16" if dtype == "<u2" else "int16", nx, ny, nz, s=spacing)
    with open(out_path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(labels.astype(dtype).tobytes())
    return int(len(np.unique(labels)) - 1)


def make_parcels(out_path, parcels=60, seed=24):
    """colin27 (1 mm) -> 2 intensity classes x `parcels` Voronoi cells inside the brain mask."""
    return write_nrrd(out_path, parcellate(colin27(), parcels, seed), 1, "<u2")


def make_atlas_2mm(out_path, parcels=96, seed=40):
    """colin27 parcels at 2 mm: 2 x `parcels` Voronoi cells made at 1 mm (classes of the image
    blurred by 2 voxels), every other voxel kept (nearest neighbour, 91 x 109 x 91)."""
    return write_nrrd(out_path, parcellate(colin27(), parcels, seed, 2)[::2, ::2, ::2], 2, "<u2")


def make_atlas_05mm(out_path, parcels=300, blobs=124, seed=41):
    """A 0.5 mm int16 atlas with many small labels: a central 84 x 103 x 64 mm box of colin27,
    upsampled x2 (trilinear), cut into 2 x `parcels` Voronoi cells (classes of the image blurred by
    3 voxels), plus `blobs` small balls
    (radius 1-3 voxels, centres drawn inside the brain) each a label of its own: 168 x 206 x 128,
    background on its faces."""
    from scipy.ndimage import zoom
    a = colin27()
    a = zoom(a[60:124, 57:160, 48:132], 2, order=1)
    labels = parcellate(a, parcels, seed, 3)
    rng = np.random.default_rng(seed)
    inside = np.argwhere(labels > 0)
    kk, jj, ii = np.indices(labels.shape, sparse=True)
    for b in range(blobs):
        c = inside[rng.integers(len(inside))]
        r = rng.uniform(1.0, 3.0)
        ball = (kk - c[0]) ** 2 + (jj - c[1]) ** 2 + (ii - c[2]) ** 2 <= r * r
        labels[ball] = 2 * parcels + 1 + b
    # Background on the box's faces: the box cuts the brain, and a structure cut open there would
    # be closed by mlfe and left open by the reference (flying edges does not pad).
    for axis in range(3):
        labels[(slice(None),) * axis + ([0, -1],)] = 0
    return write_nrrd(out_path, labels, 0.5, "<i2")


VTK_WORKER = r'''
import json, sys, time
t0 = time.perf_counter()
from vtkmodules.vtkIOImage import vtkNIFTIImageReader, vtkNrrdReader
from vtkmodules.vtkFiltersGeneral import vtkDiscreteFlyingEdges3D
from vtkmodules.vtkFiltersCore import vtkWindowedSincPolyDataFilter, vtkQuadricDecimation
from vtkmodules.vtkIOPLY import vtkPLYWriter
from vtkmodules.util.numpy_support import vtk_to_numpy
import numpy as np
path, out_dir = sys.argv[1], sys.argv[2]
r = vtkNIFTIImageReader() if ".nii" in path else vtkNrrdReader()
r.SetFileName(path)
r.Update()
img = r.GetOutput()
if ".nii" in path and r.GetQFac() < 0:
    # VTK reverses the slices of a qfac = -1 NIfTI; back to the file's voxel order.
    from vtkmodules.vtkImagingCore import vtkImageFlip
    flip = vtkImageFlip()
    flip.SetInputData(img)
    flip.SetFilteredAxis(2)
    flip.Update()
    img = flip.GetOutput()
# Index space: the distances are in voxels and mlfe's meshes are mapped back to indices.
img.SetSpacing(1, 1, 1)
img.SetOrigin(0, 0, 0)
labels = [int(v) for v in np.unique(vtk_to_numpy(img.GetPointData().GetScalars())) if v != 0]
compute = 0.0
refs, outs = {}, {}
for l in labels:
    t = time.perf_counter()
    fe = vtkDiscreteFlyingEdges3D()
    fe.SetInputData(img)
    fe.SetValue(0, l)
    fe.ComputeNormalsOff()
    fe.ComputeGradientsOff()
    fe.ComputeScalarsOff()
    fe.Update()
    sm = vtkWindowedSincPolyDataFilter()
    sm.SetInputConnection(fe.GetOutputPort())
    sm.SetNumberOfIterations(20)
    sm.SetPassBand(0.1)
    sm.BoundarySmoothingOff()
    sm.FeatureEdgeSmoothingOff()
    sm.NonManifoldSmoothingOn()
    sm.NormalizeCoordinatesOn()
    dec = vtkQuadricDecimation()
    dec.SetInputConnection(sm.GetOutputPort())
    dec.SetTargetReduction(0.9)
    dec.Update()
    compute += time.perf_counter() - t
    refs[l] = fe.GetOutput()
    outs[l] = dec.GetOutput()
seconds = time.perf_counter() - t0
triangles = sum(o.GetNumberOfPolys() for o in outs.values())
# VmHWM: the high-water mark of this address space, which exec made fresh (ru_maxrss is not: it
# starts at the parent's resident size at fork).
peak = next(float(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:")) / 1024.0
for l in labels:
    for name, poly in (("ref", refs[l]), ("vtk", outs[l])):
        w = vtkPLYWriter()
        w.SetFileName("%s/%s_%d.ply" % (out_dir, name, l))
        w.SetInputData(poly)
        w.SetFileTypeToBinary()
        w.Write()
print(json.dumps({"labels": labels, "seconds": seconds, "compute_seconds": compute, "triangles": triangles,
                  "peak_rss_mb": peak,
                  "reference_triangles": sum(o.GetNumberOfPolys() for o in refs.values())}))
'''


def run_vtk(vol, out_dir):
    p = subprocess.run([sys.executable, "-c", VTK_WORKER, vol, out_dir], check=True, capture_output=True,
                       text=True)
    return json.loads(p.stdout.strip().splitlines()[-1])


def run_mlfe(mlfe, vol, out_dir, tag, extra):
    glb = os.path.join(out_dir, tag + ".glb")
    rep = os.path.join(out_dir, tag + ".json")
    t = time.perf_counter()
    p = subprocess.run(["/usr/bin/time", "-f", "maxrss_kb %M", mlfe, "convert", vol, "--labels", "-o", glb, "--report",
                        rep, "--quiet"] + extra, check=True, capture_output=True, text=True)
    seconds = time.perf_counter() - t
    peak_kb = [float(l.split()[1]) for l in p.stderr.splitlines() if l.startswith("maxrss_kb ")][-1]
    r = json.load(open(rep))
    return glb, {"seconds": seconds, "triangles": r["asset"]["triangles"], "bytes": r["asset"]["bytes"],
                 "peak_rss_mb": peak_kb / 1024.0, "report_peak_rss_mb": r["peak_rss_mb"], "structures": r["asset"]["structure_count"],
                 "stage_seconds": r["asset"]["stage_seconds"],
                 "all_closed": all(s["closed"] for s in r["asset"]["structures"])}


def load_average():
    """The 1-minute load average now, as /proc/loadavg writes it."""
    return open("/proc/loadavg").read().split()[0]


def timed(cmd):
    """Runs cmd under /usr/bin/time; returns (process, wall seconds, user + sys seconds)."""
    p = subprocess.run(["/usr/bin/time", "-f", "TIME %e %U %S"] + cmd, capture_output=True, text=True, check=True)
    e, u, s = [float(x) for x in [l for l in p.stderr.splitlines() if l.startswith("TIME")][-1].split()[1:]]
    return p, e, u + s


def timing_rounds(mlfe, base_mlfe, vol, out_dir, rounds):
    """Time only, interleaved: per round the VTK worker, mlfe with 2 and 1 threads and (when
    given) a base build's mlfe with 2 threads. VTK's wall is its worker's own clock; CPU is user +
    sys of each process. Prints each round and the minima and medians."""
    import statistics
    glb = os.path.join(out_dir, "timing.glb")
    peers = [("mlfe, 2 threads", mlfe, 2), ("mlfe, 1 thread", mlfe, 1)]
    if base_mlfe:
        peers.append(("base mlfe, 2 threads", base_mlfe, 2))
    rows = {"VTK pipeline": []}
    rows.update({name: [] for name, _, _ in peers})
    for i in range(rounds):
        load = load_average()
        p, _, cpu = timed([sys.executable, "-c", VTK_WORKER, vol, out_dir])
        rows["VTK pipeline"].append((json.loads(p.stdout.strip().splitlines()[-1])["seconds"], cpu))
        for name, binary, threads in peers:
            _, wall, cpu = timed([binary, "--threads", str(threads), "convert", vol, "--labels", "-o", glb, "--quiet"])
            rows[name].append((wall, cpu))
        print(json.dumps({"round": i, "load": load, "wall_cpu": {k: r[-1] for k, r in rows.items()}}), flush=True)
    vtk_wall = statistics.median(x[0] for x in rows["VTK pipeline"])
    vtk_cpu = statistics.median(x[1] for x in rows["VTK pipeline"])
    for name, r in rows.items():
        wall, cpu = [x[0] for x in r], [x[1] for x in r]
        print("%-22s wall min %.2f median %.2f  cpu min %.2f median %.2f  median/VTK wall %.2f cpu %.2f" %
              (name, min(wall), statistics.median(wall), min(cpu), statistics.median(cpu),
               statistics.median(wall) / vtk_wall, statistics.median(cpu) / vtk_cpu), flush=True)


SURFACE_NETS_MODES = (("sn_smooth", "on"), ("sn_raw", "off"))


def surface_nets_tool(build, given):
    """The Surface Nets tool's path, or "" (the skip printed) when it is not there."""
    path = given or os.path.join(build, "bench-peers", "surface_nets_labels")
    if os.access(path, os.X_OK):
        return path
    print("labels_bench: skipping Surface Nets (vtkSurfaceNets3D, VTK >= 9.3): no tool at %s" % path, flush=True)
    return ""


def run_surface_nets(tool, vol, out_dir, prefix, smoothing, rounds=3):
    """The tool's report with the median seconds of `rounds` runs (its clock is ~0.1 s, a few
    scheduler slices on a loaded machine); the meshes are the last run's (the output is
    deterministic)."""
    runs = [json.loads(subprocess.run([tool, vol, out_dir, prefix, "--smoothing", smoothing, "--threads", "2"],
                                      check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1])
            for _ in range(rounds)]
    median = {k: float(np.median([r[k] for r in runs])) for k in ("seconds", "filter_seconds", "peak_rss_mb")}
    return runs[-1] | median | {"seconds_runs": [r["seconds"] for r in runs]}


def distances(build, vol, glb, out_dir, peers):
    tool = os.path.join(build, "bench", "label_distance_bench")
    p = subprocess.run([tool, vol, glb, out_dir] + peers, check=True, capture_output=True, text=True)
    return json.loads(p.stdout)


def summary(rows, key):
    means = [r[key]["mean"] for r in rows]
    hd = [r[key]["hausdorff"] for r in rows]
    big = [r[key]["mean"] for r in rows if r["voxels"] >= 100]
    return {"mean_max": max(means), "mean_median": float(np.median(means)), "hausdorff_max": max(hd),
            "hausdorff_median": float(np.median(hd)), "mean_max_ge100_voxels": max(big, default=0.0),
            "labels_mean_le_0.15": sum(m <= 0.15 for m in means), "labels_hausdorff_le_1.5": sum(h <= 1.5 for h in hd),
            "triangles": sum(r[key]["triangles"] for r in rows),
            "labels_closed": sum(r[key]["closed"] for r in rows),
            "labels_manifold": sum(r[key]["manifold"] for r in rows),
            "non_manifold_edges": sum(r[key].get("non_manifold_edges", 0) for r in rows),
            "non_manifold_vertices": sum(r[key].get("non_manifold_vertices", 0) for r in rows),
            "inconsistent_edges": sum(r[key].get("inconsistent_edges", 0) for r in rows)}


def print_table(results):
    """One Markdown row per atlas and method (time, peak, triangles, error, topology)."""
    print("| atlas | method | load | s | peak MB | triangles (shared) | worst mean >= 100 vox (median) "
          "| worst Hausdorff (median) | closed / manifold labels | non-manifold edges / vertices |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for tag, r in results.items():
        for key in ["mlfe", "vtk"] + [k for k, _ in SURFACE_NETS_MODES if k in r]:
            m, d, n = r[key], r[key + "_distance"], len(r["per_label"])
            shared = " (%d)" % m["shared_triangles"] if "shared_triangles" in m else ""
            print("| %s | %s | %s | %.2f | %.0f | %d%s | %.3f (%.3f) | %.2f (%.2f) | %d / %d of %d | %d / %d |" %
                  (tag, key, m["load"], m["seconds"], m["peak_rss_mb"], d["triangles"], shared,
                   d["mean_max_ge100_voxels"], d["mean_median"], d["hausdorff_max"], d["hausdorff_median"],
                   d["labels_closed"], d["labels_manifold"], n, d["non_manifold_edges"], d["non_manifold_vertices"]))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default=os.path.join(HERE, "..", "..", "build"))
    ap.add_argument("--out", default="/tmp/labels_bench")
    ap.add_argument("--mlfe-args", default="", help="extra mlfe convert options")
    ap.add_argument("--volumes", default="jhu,parcels", help="which volumes, comma-separated: jhu, parcels (1 mm), atlas2mm, atlas05mm")
    ap.add_argument("--timing-rounds", type=int, default=0,
                    help="instead: this many interleaved timing rounds on the JHU atlas (no distances)")
    ap.add_argument("--base-build", default="", help="with --timing-rounds: a second build to time beside")
    ap.add_argument("--surface-nets", default="",
                    help="the vtkSurfaceNets3D tool (default <build>/bench-peers/surface_nets_labels; skipped if absent)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    mlfe = mlfe_binary(args.build)
    if args.timing_rounds > 0:
        base = mlfe_binary(args.base_build) if args.base_build else ""
        timing_rounds(mlfe, base, os.path.join(SHARED, "atlas_jhu_wm_labels_1mm.nii.gz"), args.out,
                      args.timing_rounds)
        return
    wanted = args.volumes.split(",")
    volumes = []
    if "jhu" in wanted:
        volumes.append(("jhu_atlas", os.path.join(SHARED, "atlas_jhu_wm_labels_1mm.nii.gz")))
    makers = {"parcels": ("colin27_parcels_1mm", make_parcels), "atlas2mm": ("colin27_parcels_2mm", make_atlas_2mm),
              "atlas05mm": ("colin27_parcels_05mm_int16", make_atlas_05mm)}
    for key, (name, make) in makers.items():
        if key in wanted:
            path = os.path.join(args.out, name + ".nrrd")
            volumes.append(("%s_%d" % (name, make(path)), path))
    sn_tool = surface_nets_tool(args.build, args.surface_nets)
    results = {}
    for tag, vol in volumes:
        d = os.path.join(args.out, tag)
        os.makedirs(d, exist_ok=True)
        vtk = run_vtk(vol, d) | {"load": load_average()}
        glb, m = run_mlfe(mlfe, vol, d, "mlfe", args.mlfe_args.split())
        r = {"mlfe": m | {"load": load_average()}}
        peers = []
        for prefix, smoothing in SURFACE_NETS_MODES if sn_tool else ():
            sn = run_surface_nets(sn_tool, vol, d, prefix, smoothing)
            sn["shared_triangles"] = sn.pop("triangles")
            r[prefix] = sn | {"load": load_average()}
            peers.append(prefix)
        dist = distances(args.build, vol, glb, d, peers)
        vtk.pop("labels")
        r["vtk"] = vtk | {"bytes": dist["vtk_glb_bytes"]}
        for key in ["mlfe", "vtk"] + peers:
            r[key + "_distance"] = summary(dist["labels"], key)
        results[tag] = r | {"per_label": dist["labels"]}
        print(json.dumps({tag: {k: v for k, v in results[tag].items() if k != "per_label"}}, indent=1), flush=True)
    json.dump(results, open(os.path.join(args.out, "results.json"), "w"), indent=1)
    print_table(results)


if __name__ == "__main__":
    main()
