#!/usr/bin/python3
"""Issue #40's triangle target against its error targets: how few triangles can any per-label mesh
have with a worst mean <= 0.15 voxel (labels of >= 100 voxels) and a worst Hausdorff <= 1.5 voxels?

Per atlas of bench/py/labels_bench.py (same makers, same references: each label's voxel-boundary
surface, discrete flying edges), this measures two trade-off curves in one run:
  - The reference itself decimated: every label's reference mesh, unsmoothed (the surface the
    distances are measured to, so the most favourable input there is), through VTK's
    vtkQuadricDecimation (the Slicer-like pipeline's own decimator) at target reductions 0.5 ..
    0.95. Then, per label, the largest reduction whose mesh meets the error targets is picked
    (an oracle: it measures each candidate against the reference, which no pipeline can), and the
    picked meshes' triangles are summed. The sum is printed with the Hausdorff target relaxed to
    3, 2 and none as well, to show which target binds.
  - mlfe's own curve: `mlfe convert --labels` at several --simplify tolerances.
Triangles are given as a multiple of the Slicer-like pipeline's (decimation to 10 %), measured in
the same run. Distances: bench/cpp/label_distance_bench (symmetric Hausdorff and the larger
one-sided mean, in voxels).

  /usr/bin/python3 bench/py/labels_frontier.py --build build --out /tmp/labels_frontier
  /usr/bin/python3 bench/py/labels_frontier.py --volumes atlas2mm --tolerances 0.25,0.34,0.5
"""
import argparse
import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import labels_bench  # noqa: E402
from bench_paths import mlfe_binary  # noqa: E402

RATIOS = (50, 60, 70, 75, 80, 85, 90, 93, 95)

DECIMATE_WORKER = r'''
import glob, sys
from vtkmodules.vtkIOPLY import vtkPLYReader, vtkPLYWriter
from vtkmodules.vtkFiltersCore import vtkQuadricDecimation
d, ratio = sys.argv[1], int(sys.argv[2])
for f in sorted(glob.glob(d + "/ref_*.ply")):
    label = f.rsplit("_", 1)[1][:-4]
    r = vtkPLYReader()
    r.SetFileName(f)
    q = vtkQuadricDecimation()
    q.SetInputConnection(r.GetOutputPort())
    q.SetTargetReduction(ratio / 100.0)
    q.Update()
    w = vtkPLYWriter()
    w.SetFileName("%s/q%d_%s.ply" % (d, ratio, label))
    w.SetInputData(q.GetOutput())
    w.SetFileTypeToBinary()
    w.Write()
'''


def worst(rows, key):
    """(triangles, worst mean over labels of >= 100 voxels, worst Hausdorff) of one method."""
    big = [r[key]["mean"] for r in rows if r["voxels"] >= 100]
    return (sum(r[key]["triangles"] for r in rows), max(big, default=0.0), max(r[key]["hausdorff"] for r in rows))


def oracle(rows, keys, mean_target, hausdorff_target):
    """Per label the mesh of the largest reduction (keys from most to least reduced) that meets
    both targets (the least reduced when none does); their triangle sum and how many labels
    missed."""
    total, missed = 0, 0
    for r in rows:
        need = mean_target if r["voxels"] >= 100 else float("inf")
        ok = [k for k in keys if r[k]["mean"] <= need and r[k]["hausdorff"] <= hausdorff_target]
        missed += not ok
        total += r[ok[0] if ok else keys[-1]]["triangles"]
    return total, missed


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default=os.path.join(labels_bench.HERE, "..", "..", "build"))
    ap.add_argument("--out", default="/tmp/labels_frontier")
    ap.add_argument("--volumes", default="parcels,atlas2mm,atlas05mm")
    ap.add_argument("--tolerances", default="0.2,0.25,0.34,0.5", help="mlfe --simplify values")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    mlfe = mlfe_binary(args.build)
    makers = {"parcels": ("colin27_parcels_1mm", labels_bench.make_parcels),
              "atlas2mm": ("colin27_parcels_2mm", labels_bench.make_atlas_2mm),
              "atlas05mm": ("colin27_parcels_05mm_int16", labels_bench.make_atlas_05mm)}
    tolerances = [float(t) for t in args.tolerances.split(",")]
    results = {}
    for key in args.volumes.split(","):
        name, make = makers[key]
        vol = os.path.join(args.out, name + ".nrrd")
        tag = "%s_%d" % (name, make(vol))
        d = os.path.join(args.out, tag)
        os.makedirs(d, exist_ok=True)
        vtk = labels_bench.run_vtk(vol, d)
        for ratio in RATIOS:
            subprocess.run([sys.executable, "-c", DECIMATE_WORKER, d, str(ratio)], check=True)
        qkeys = ["q%d" % r for r in RATIOS]
        curves = {"vtk_triangles": vtk["triangles"], "reference_decimated": {}, "oracle": {}, "mlfe": {}}
        for t in tolerances:
            glb, m = labels_bench.run_mlfe(mlfe, vol, d, "mlfe_%g" % t, ["--simplify", str(t)])
            rows = labels_bench.distances(args.build, vol, glb, d, qkeys if t == tolerances[0] else [])["labels"]
            curves["mlfe"][str(t)] = worst(rows, "mlfe") + (m["seconds"],)
            if t == tolerances[0]:
                for k in qkeys:
                    curves["reference_decimated"][k] = worst(rows, k)
                for h in (float("inf"), 3.0, 2.0, 1.5):
                    curves["oracle"][str(h)] = oracle(rows, qkeys[::-1], 0.15, h)
        results[tag] = curves
        v = float(vtk["triangles"])
        print("## %s: Slicer-like pipeline %d triangles" % (tag, vtk["triangles"]), flush=True)
        print("| method | triangles (x Slicer-like) | worst mean >= 100 vox | worst Hausdorff |")
        print("|---|---|---|---|")
        for k, (n, mean, hd) in curves["reference_decimated"].items():
            print("| reference, quadric decimation to %d %% | %d (%.2fx) | %.3f | %.2f |" % (100 - int(k[1:]), n, n / v, mean, hd))
        for t, (n, mean, hd, s) in curves["mlfe"].items():
            print("| mlfe --simplify %s (%.1f s) | %d (%.2fx) | %.3f | %.2f |" % (t, s, n, n / v, mean, hd))
        for h, (n, missed) in curves["oracle"].items():
            print("| oracle per label: mean <= 0.15 and Hausdorff <= %s | %d (%.2fx) | labels missing: %d | |" % (
                h, n, n / v, missed))
    json.dump(results, open(os.path.join(args.out, "frontier.json"), "w"), indent=1)


if __name__ == "__main__":
    main()
