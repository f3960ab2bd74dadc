#!/usr/bin/env python3
"""Issue #16 gap analysis: how much of the hierarchy file's size on the Colin27 MRI comes from
the mesh lattice not falling on the voxels?

`mlfe build` starts from one box over the volume's extent, so on a 181x217x181 volume the
vertices of level k sit at extent / 2^k: 0.70 x 0.84 x 0.70 voxels on level 8, never on a voxel
on any level. This script pads the volume with zeros to 257^3 (the background of the
brain-extracted scan is 0, so the padding is flat and costs the hierarchy nothing but coarse
elements), where level 8's vertices are exactly the voxels, builds it with the RMS target scaled
so that the error over the original voxels matches the default's (0.5 % of the range over the
original domain: the padded domain's L2 mean is diluted by the ratio of the volumes), caps the
level at 8, exports the decoded approximation and measures it on the original voxels only.

    /usr/bin/python3 bench/py/hierarchy_lattice_experiment.py [--mlfe build/converters/cli/mlfe]

Prints one markdown table row per build: the unpadded default and the padded, aligned one.
"""
import argparse
import json
import math
import os
import subprocess
import time

import numpy as np

from hierarchy_file_bench import errors, read_voxels


def build_and_measure(mlfe, inp, out, opts, orig):
    """Builds `inp`, exports the decoded approximation and measures it on the voxels of `orig`
    (its leading corner when the input was padded); orig is indexed [k, j, i]."""
    h = os.path.join(out, os.path.basename(inp).split(".")[0] + ".mlfeh")
    rep = h + ".json"
    t0 = time.perf_counter()
    subprocess.run([mlfe, "build", inp, "-o", h, "--report", rep, "--quiet"] + opts, check=True)
    secs = time.perf_counter() - t0
    x = os.path.join(out, "decoded.raw")
    subprocess.run([mlfe, "export", h, "-o", x], check=True, stdout=subprocess.DEVNULL)
    dims = json.load(open(x + ".json"))["dims"]
    dec = np.fromfile(x, dtype=np.float32).reshape(dims[2], dims[1], dims[0])
    nz, ny, nx = orig.shape
    e = errors(dec[:nz, :ny, :nx], orig, 133.0)
    size = os.path.getsize(h)
    return {"opts": " ".join(opts) or "(default)", "vertices": json.load(open(rep)).get("vertices"),
            "bytes": size, "bpv": 8 * size / orig.size, "psnr": e["psnr_db"], "max": e["max"], "seconds": secs}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mlfe", default=os.path.join(os.path.dirname(__file__), "..", "..", "build", "converters", "cli", "mlfe"))
    ap.add_argument("--data", default="/work/shared/data")
    ap.add_argument("--out", default="/tmp/mlfe_lattice_experiment")
    a = ap.parse_args()
    mlfe = os.path.abspath(a.mlfe)
    os.makedirs(a.out, exist_ok=True)
    src = os.path.join(a.data, "mri_colin27_brain.nii.gz")
    flat, (nx, ny, nz) = read_voxels(src)
    vol = flat.reshape(nz, ny, nx)
    pad = np.zeros((257, 257, 257), np.uint8)
    pad[:nz, :ny, :nx] = vol
    praw = os.path.join(a.out, "colin27_pad257.raw")
    pad.tofile(praw)
    json.dump({"dims": [257, 257, 257], "dtype": "uint8"}, open(praw + ".json", "w"))
    # The default target, 0.5 % of the range 0..133 over the original domain, as an absolute RMS
    # over the padded domain (error in the flat padding ~0).
    rms_pad = 0.005 * 133 * math.sqrt(vol.size / pad.size)
    rows = [build_and_measure(mlfe, src, a.out, [], vol),
            build_and_measure(mlfe, praw, a.out, ["--rms", f"{rms_pad:.4f}", "--max-level", "8"], vol)]
    print(f"date {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load {os.getloadavg()[0]:.2f}\n")
    print("| build | vertices | bytes | bpv (original voxels) | PSNR dB | max error | build s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for label, r in zip(["box over the extent (mlfe build default)", "padded to 257^3, level 8 = voxels"], rows):
        print(f"| {label}: {r['opts']} | {r['vertices']} | {r['bytes']} | {r['bpv']:.3f} | {r['psnr']:.2f} | "
              f"{r['max']:.1f} | {r['seconds']:.1f} |")


if __name__ == "__main__":
    main()
