#!/usr/bin/env python3
"""The hierarchy on the samples' lattice (issue #23): `mlfe build` on a noisy scan.

1. The default target against the noise: builds the noisy volume with RMS targets k·σ (σ the
   noise level the default build estimates and reports) and measures each build's decoded
   values against the NOISELESS volume it was made from (bench/data/make_fullhead.py --sigma 0),
   besides the noisy one: the k whose error against the clean signal is smallest stores the
   signal and not the noise.
2. A vertex budget of 1/8 of the voxels against uniform 2x downsampling (every second sample,
   trilinear back to the grid), PSNR over the value range on the voxels.

Usage: /usr/bin/python3 bench/py/lattice_bench.py --mlfe build/converters/cli/mlfe
           --noisy /work/data/fullhead_1mm.nii.gz --clean /work/data/fullhead_1mm_clean.nii.gz
           [--factors 0.5,0.75,1,1.5,2] [--out /tmp/lattice_bench]
Prints Markdown tables and writes OUT/results.json.
"""
import argparse
import json
import math
import os
import subprocess
import time

import numpy as np
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOImage import vtkNIFTIImageReader, vtkNrrdReader


def read_voxels(path):
    """Voxels as float64 indexed [k, j, i] (x fastest in memory), and the dims (nx, ny, nz)."""
    r = vtkNIFTIImageReader() if ".nii" in path else vtkNrrdReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    nx, ny, nz = img.GetDimensions()
    v = vtk_to_numpy(img.GetPointData().GetScalars()).astype(np.float64)
    return v.reshape(nz, ny, nx), (nx, ny, nz)


def errors(a, b, peak):
    d = a - b
    rms = math.sqrt(float(np.mean(d * d)))
    return {"rms": rms, "max": float(np.max(np.abs(d))),
            "psnr_db": 20 * math.log10(peak / rms) if rms > 0 else float("inf")}


def decoded(mlfe, h, dims, out_dir):
    """`mlfe export` of the file on the data's grid (cropped when the writer pads)."""
    x = os.path.join(out_dir, "decoded.raw")
    t = time.perf_counter()
    p = subprocess.run([mlfe, "export", h, "-o", x], check=True, capture_output=True, text=True)
    seconds = time.perf_counter() - t
    meta = json.load(open(x + ".json")) if os.path.exists(x + ".json") else None
    v = np.fromfile(x, dtype="<f4").astype(np.float64)
    os.remove(x)
    ed = meta["dims"] if meta else dims
    v = v.reshape(ed[2], ed[1], ed[0])[: dims[2], : dims[1], : dims[0]]
    return v, seconds, p.stderr


def build(mlfe, inp, opts, out_dir, tag):
    h = os.path.join(out_dir, tag + ".mlfeh")
    rep = os.path.join(out_dir, tag + ".json")
    t = time.perf_counter()
    subprocess.run(["/usr/bin/time", "-f", "%M", mlfe, "build", inp, "-o", h, "--report", rep, "--quiet"] + opts,
                   check=True, capture_output=True)
    seconds = time.perf_counter() - t
    r = json.load(open(rep))
    return h, r, seconds


def upsample_axis(v, axis, n):
    """Linear interpolation along `axis` from samples at 0, 2, 4, ... (and n−1) back to n."""
    idx = list(range(0, n, 2))
    if idx[-1] != n - 1:
        idx.append(n - 1)
    src = np.take(v, range(len(idx)), axis=axis)
    pos = np.array(idx, dtype=np.float64)
    x = np.arange(n, dtype=np.float64)
    hi = np.clip(np.searchsorted(pos, x, side="right"), 1, len(pos) - 1)
    lo = hi - 1
    t = (x - pos[lo]) / (pos[hi] - pos[lo])
    shape = [1] * v.ndim
    shape[axis] = n
    a = np.take(src, lo, axis=axis)
    b = np.take(src, hi, axis=axis)
    return a + (b - a) * t.reshape(shape)


def downsample2(v):
    nz, ny, nx = v.shape
    keep = [sorted(set(list(range(0, n, 2)) + [n - 1])) for n in (nz, ny, nx)]
    sub = v[np.ix_(*keep)]
    out = sub
    for axis, n in enumerate((nz, ny, nx)):
        out = upsample_axis(out, axis, n)
    return out, sub.size


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mlfe", default="build/converters/cli/mlfe")
    ap.add_argument("--noisy", required=True)
    ap.add_argument("--clean", required=True)
    ap.add_argument("--factors", default="0.5,0.75,1,1.5,2")
    ap.add_argument("--out", default="/tmp/lattice_bench")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    noisy, dims = read_voxels(a.noisy)
    clean, _ = read_voxels(a.clean)
    peak = float(noisy.max() - noisy.min())
    n = noisy.size
    rows = []

    def row(label, opts, tag):
        h, r, seconds = build(a.mlfe, a.noisy, opts, a.out, tag)
        v, dec_s, _ = decoded(a.mlfe, h, dims, a.out)
        e_noisy = errors(v, noisy, peak)
        e_clean = errors(v, clean, peak)
        f = r["file"]
        rows.append({"setting": label, "vertices": r["vertices"], "bytes": f["bytes"], "bpv": f["bits_per_voxel"],
                     "psnr_noisy": e_noisy["psnr_db"], "max_noisy": e_noisy["max"], "rms_clean": e_clean["rms"],
                     "psnr_clean": e_clean["psnr_db"], "seconds": seconds, "peak_mb": r["peak_rss_mb"],
                     "decode_s": dec_s, "noise_sigma": r.get("noise_sigma"), "target": r.get("rms_target")})
        return r

    r0 = row("default", [], "default")
    sigma = r0.get("noise_sigma", 0.0)
    for k in [float(x) for x in a.factors.split(",")]:
        row(f"--rms {k:g}σ = {k * sigma:.3f}", ["--rms", f"{k * sigma:.6f}"], f"k{k:g}")
    budget = n // 8
    row(f"--max-vertices {budget} (voxels/8)", ["--max-vertices", str(budget)], "budget")
    up, kept = downsample2(noisy)
    e = errors(up, noisy, peak)
    ec = errors(up, clean, peak)
    rows.append({"setting": f"uniform 2x downsampling ({kept} samples), trilinear back", "vertices": kept,
                 "bytes": None, "bpv": None, "psnr_noisy": e["psnr_db"], "max_noisy": e["max"],
                 "rms_clean": ec["rms"], "psnr_clean": ec["psnr_db"], "seconds": None, "peak_mb": None,
                 "decode_s": None})
    e = errors(noisy, clean, peak)
    print(f"noisy input against the clean volume: RMS {e['rms']:.3f}, PSNR {e['psnr_db']:.2f} dB; "
          f"estimated noise sigma {sigma:.3f}; {n} voxels, dims {dims}")
    print("| setting | vertices | bytes | bpv | PSNR noisy dB | max err noisy | RMS vs clean | PSNR clean dB | build s | peak MiB |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for x in rows:
        def f(v, fmt):
            return "" if v is None else format(v, fmt)
        print(f"| {x['setting']} | {x['vertices']} | {f(x['bytes'], '.0f')} | {f(x['bpv'], '.3f')} | "
              f"{x['psnr_noisy']:.2f} | {x['max_noisy']:.1f} | {x['rms_clean']:.3f} | {x['psnr_clean']:.2f} | "
              f"{f(x['seconds'], '.2f')} | {f(x['peak_mb'], '.0f')} |")
    json.dump(rows, open(os.path.join(a.out, "results.json"), "w"), indent=1)


if __name__ == "__main__":
    main()
