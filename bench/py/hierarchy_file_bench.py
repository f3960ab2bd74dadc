#!/usr/bin/env python3
"""Rate-distortion of the mlfe hierarchy file (issue #16) beside ZFP fixed-accuracy and
lossless zstd -19 / gzip -9 of the raw input.

For each input and each `mlfe build` setting: file bits per voxel, PSNR (voxel grid, value
range as peak) and max error from the build report, encode seconds (the whole `mlfe build`
wall time and the report's encode figure), and decode seconds (`mlfe export H -o X.raw`: read,
rebuild, resample the full grid, write). ZFP (python3-zfpy) compresses the voxels as float32
at several tolerances; its PSNR and max error are measured the same way.

With --max-error (issue #23): error-bounded and lossless files instead: `mlfe build
--max-error E` for E = 0 (lossless on integer data, checked voxel for voxel after export) and a
few E relative to the value range, against ZFP fixed-accuracy at tolerance E (equal max error)
and ZFP interpolated to mlfe's PSNR (equal PSNR); inputs: the CT, the brain MRI and a noisy full
head (--fullhead, default /work/data/fullhead.nii.gz; make one with bench/data/make_fullhead.py).
--share S1,S2 adds rows with `--quantization-share S` (how E is split; chosen by measurement).

Usage: /usr/bin/python3 bench/py/hierarchy_file_bench.py [--mlfe build/converters/cli/mlfe]
           [--data /work/shared/data] [--out /tmp/hfile_bench] [--quick] [--max-error]
Prints a Markdown table and writes OUT/results.json. Dependencies: scripts/install_bench_deps.sh.
"""
import argparse
import gzip
import json
import math
import os
import resource
import subprocess
import sys
import time

import numpy as np
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOImage import vtkNIFTIImageReader, vtkNrrdReader

try:
    import zfpy
except ImportError:  # the table then lacks the ZFP rows
    zfpy = None


def read_voxels(path):
    """Voxels in their stored type, x fastest (VTK's point order)."""
    r = vtkNIFTIImageReader() if ".nii" in path else vtkNrrdReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    return vtk_to_numpy(img.GetPointData().GetScalars()).copy(), img.GetDimensions()


def child_cpu_s():
    """CPU seconds (user + system) of the finished child processes so far: on a loaded machine a
    single-threaded command's CPU time stays close to its unloaded wall time, which its wall does not."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def errors(a, b, peak):
    d = a.astype(np.float64) - b.astype(np.float64)
    rms = math.sqrt(float(np.mean(d * d)))
    return {"rms": rms, "max": float(np.max(np.abs(d))),
            "psnr_db": 20 * math.log10(peak / rms) if rms > 0 else float("inf")}


def lossless(raw_path, n):
    rows = []
    for name, cmd in (("zstd -19", ["zstd", "-19", "-q", "-c", raw_path]), ("gzip -9", ["gzip", "-9", "-c", raw_path])):
        t = time.perf_counter()
        out = subprocess.run(cmd, check=True, capture_output=True).stdout
        rows.append({"coder": name, "bytes": len(out), "bpv": 8 * len(out) / n, "encode_s": time.perf_counter() - t})
    return rows


def run_mlfe(mlfe, inp, opts, out_dir, tag, n, global_opts=()):
    """`mlfe [global_opts] build inp opts`, then `mlfe export` of the file: the report's figures, the
    wall and CPU times and the decoded voxels (float32)."""
    h = os.path.join(out_dir, tag + ".mlfeh")
    rep = os.path.join(out_dir, tag + ".json")
    cpu = child_cpu_s()
    t = time.perf_counter()
    subprocess.run([mlfe, *global_opts, "build", inp, "-o", h, "--report", rep] + opts, check=True, capture_output=True)
    build_s = time.perf_counter() - t
    build_cpu_s = child_cpu_s() - cpu
    f = json.load(open(rep))["file"]
    x = os.path.join(out_dir, tag + "_decoded.raw")
    cpu = child_cpu_s()
    t = time.perf_counter()
    p = subprocess.run([mlfe, *global_opts, "export", h, "-o", x], check=True, capture_output=True, text=True)
    decode_s = time.perf_counter() - t
    decode_cpu_s = child_cpu_s() - cpu
    resample = float(p.stderr.split("resampled in ")[1].split(" s")[0])
    decoded = np.fromfile(x, dtype="<f4")
    os.remove(x)
    assert decoded.size == n, (decoded.size, n)
    return {"coder": "mlfe " + (" ".join(opts) or "default"), "bytes": f["bytes"], "bpv": f["bits_per_voxel"],
            "psnr_db": f["psnr_db"], "rms": f["rms_error"], "max": f["max_error"], "bound": f["value_bound"],
            "encode_s": f["encode_seconds"], "build_s": build_s, "decode_s": decode_s,
            "build_cpu_s": build_cpu_s, "decode_cpu_s": decode_cpu_s,
            "resample_s": resample, "decoded": decoded}


def run_zfp(vox, dims, tol, peak, clock=time.perf_counter):
    """ZFP fixed-accuracy at `tol`; seconds by `clock` (time.process_time: CPU seconds)."""
    a = vox.astype(np.float32).reshape(dims[2], dims[1], dims[0])
    t = clock()
    c = zfpy.compress_numpy(a, tolerance=tol)
    enc = clock() - t
    t = clock()
    d = zfpy.decompress_numpy(c)
    dec = clock() - t
    e = errors(d.ravel(), vox, peak)
    return {"coder": f"ZFP accuracy {tol:g}", "bytes": len(c), "bpv": 8 * len(c) / vox.size, "psnr_db": e["psnr_db"],
            "rms": e["rms"], "max": e["max"], "encode_s": enc, "decode_s": dec}


def zfp_bpv_at(points, psnr):
    """ZFP's bits per voxel at `psnr`, interpolated linearly in PSNR between the two measured
    tolerances around it (rate is close to linear in PSNR over one tolerance doubling); None
    outside the measured range."""
    for (p0, b0), (p1, b1) in zip(points, points[1:]):
        if p0 <= psnr <= p1 and p1 > p0:
            return b0 + (psnr - p0) / (p1 - p0) * (b1 - b0)
    return None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mlfe", default=os.path.join(os.path.dirname(__file__), "..", "..", "build", "converters", "cli", "mlfe"))
    ap.add_argument("--data", default="/work/shared/data")
    ap.add_argument("--out", default="/tmp/hfile_bench")
    ap.add_argument("--quick", action="store_true", help="one mlfe setting per input")
    ap.add_argument("--max-error", action="store_true", help="error-bounded and lossless files (issue #23)")
    ap.add_argument("--fullhead", default="/work/data/fullhead.nii.gz")
    ap.add_argument("--share", default="", help="quantization shares to try at the middle E, e.g. 0.25,0.75")
    ap.add_argument("--only", default="", help="comma-separated input names (CT, MRI, HEAD)")
    ap.add_argument("--bounds", default="", help="E values to run instead of the defaults (as in the table: "
                    "data units for integer inputs, fractions of the range for float ones), e.g. 2,8")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    if args.max_error:
        return max_error_main(args)
    cases = [
        ("CT", "ct_skull_64.nrrd",
         [[], ["--max-error", "0.05"], ["--rms", "0.25%"], ["--rms", "0.1%"], ["--rms", "1%"], ["--rms", "2%"],
          ["--rms", "4%"]],
         [0.1, 0.25, 0.5, 1, 2, 4, 8, 16, 32]),
        ("MRI", "mri_colin27_brain.nii.gz", [[], ["--rms", "1%"], ["--rms", "2%"], ["--rms", "4%"]],
         [4, 8, 16, 32, 64, 128, 256, 512, 1024]),
    ]
    results = {"load_average": os.getloadavg(), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
               "inputs": {}}
    for name, file, settings, tols in cases:
        inp = os.path.join(args.data, file)
        vox, dims = read_voxels(inp)
        n = vox.size
        peak = float(vox.max()) - float(vox.min())
        raw = os.path.join(args.out, name + ".raw")
        vox.tofile(raw)
        rows = lossless(raw, n)
        for i, opts in enumerate(settings[:1] if args.quick else settings):
            r = run_mlfe(os.path.abspath(args.mlfe), inp, opts, args.out, f"{name}_{i}", n)
            e = errors(r.pop("decoded"), vox, peak)
            r["psnr_check_db"] = e["psnr_db"]  # the report's figure, recomputed from the export
            rows.append(r)
            print(name, r["coder"], f"{r['bpv']:.3f} bpv {r['psnr_db']:.2f} dB", file=sys.stderr)
        if zfpy:
            rows += [run_zfp(vox, dims, t, peak) for t in tols]
        results["inputs"][name] = {"file": file, "dims": dims, "dtype": str(vox.dtype), "voxels": n,
                                   "raw_bytes": vox.nbytes, "rows": rows}
    results["load_average_end"] = os.getloadavg()
    json.dump(results, open(os.path.join(args.out, "results.json"), "w"), indent=1)
    print(f"date {results['date']}, load average {results['load_average'][0]:.2f} (start) "
          f"{results['load_average_end'][0]:.2f} (end)")
    for name, r in results["inputs"].items():
        print(f"\n{name}: {r['file']} {r['dims']} {r['dtype']}, {r['voxels']} voxels, raw {r['raw_bytes']} bytes\n")
        zfp = sorted((x["psnr_db"], x["bpv"]) for x in r["rows"] if x["coder"].startswith("ZFP"))
        print("| coder | bytes | bpv | PSNR dB | max error | encode s | decode s | ZFP bpv at this PSNR |")
        print("|---|---|---|---|---|---|---|---|")
        for x in r["rows"]:
            psnr = f"{x['psnr_db']:.2f}" if "psnr_db" in x else "lossless"
            mx = f"{x['max']:.4g}" if "max" in x else "0"
            enc = f"{x['encode_s']:.2f}" + (f" (build {x['build_s']:.1f})" if "build_s" in x else "")
            dec = f"{x['decode_s']:.2f}" + (f" (resample {x['resample_s']:.2f})" if "resample_s" in x else "") \
                if "decode_s" in x else ""
            eq = ""
            if x["coder"].startswith("mlfe"):
                z = zfp_bpv_at(zfp, x["psnr_db"])
                eq = f"{z:.3f} (mlfe {x['bpv'] / z:.2f}x)" if z else "outside ZFP's range"
            print(f"| {x['coder']} | {x['bytes']} | {x['bpv']:.3f} | {psnr} | {mx} | {enc} | {dec} | {eq} |")


def max_error_main(args):
    cases = [("CT", os.path.join(args.data, "ct_skull_64.nrrd"), [0.001, 0.005, 0.02]),
             ("MRI", os.path.join(args.data, "mri_colin27_brain.nii.gz"), [1, 2, 4, 8]),
             ("HEAD", args.fullhead, [1, 2, 4, 8])]
    only = set(filter(None, args.only.split(",")))
    shares = [float(x) for x in filter(None, args.share.split(","))]
    results = {"load_average": os.getloadavg(), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
               "machine": os.uname().nodename + ", " + str(os.cpu_count()) + " cores", "inputs": {}}
    for name, inp, es in cases:
        if (only and name not in only) or not os.path.exists(inp):
            continue
        vox, dims = read_voxels(inp)
        n = vox.size
        peak = float(vox.max()) - float(vox.min())
        integer = vox.dtype.kind in "iu"
        # Integer data: E in data units; float data: E as a fraction of the value range.
        if args.bounds:
            es = [float(x) for x in args.bounds.split(",")]
        bounds = [0] + [e if integer else e * peak for e in es]
        raw = os.path.join(args.out, name + ".raw")
        vox.tofile(raw)
        rows = lossless(raw, n)
        os.remove(raw)
        for i, e in enumerate(bounds):
            opt_sets = [["--max-error", f"{e:.6g}"]]
            if shares and i == len(bounds) // 2:
                opt_sets += [["--max-error", f"{e:.6g}", "--quantization-share", str(s)] for s in shares]
            for j, opts in enumerate(opt_sets):
                r = run_mlfe(os.path.abspath(args.mlfe), inp, opts + ["--quiet"], args.out, f"{name}_e{i}_{j}", n)
                d = r.pop("decoded")
                if r["psnr_db"] is None:  # the report's JSON has no infinity: lossless
                    r["psnr_db"] = float("inf")
                err = errors(d, vox, peak)
                r["max_check"] = err["max"]  # from the export, voxel for voxel
                r["bound_e"] = e
                r["lossless_check"] = bool(e == 0 and np.array_equal(d, vox.astype(np.float32)))
                assert err["max"] <= e * (1 + 1e-6) + 1e-12, (name, opts, err["max"])
                rows.append(r)
                print(name, r["coder"], f"{r['bpv']:.3f} bpv {r['psnr_db']:.2f} dB max {err['max']:.4g}",
                      file=sys.stderr)
            if zfpy and e > 0:
                z = run_zfp(vox, dims, e, peak)
                z["coder"] = f"ZFP accuracy {e:.6g} (equal max error)"
                rows.append(z)
        if zfpy:
            zt = [peak * 2.0 ** -k for k in range(2, 16)]
            zpts = sorted((x["psnr_db"], x["bpv"]) for x in (run_zfp(vox, dims, t, peak) for t in zt))
            for x in rows:
                if x["coder"].startswith("mlfe") and math.isfinite(x["psnr_db"]):
                    x["zfp_bpv_equal_psnr"] = zfp_bpv_at(zpts, x["psnr_db"])
        results["inputs"][name] = {"file": inp, "dims": dims, "dtype": str(vox.dtype), "voxels": n,
                                   "raw_bytes": vox.nbytes, "rows": rows}
    results["load_average_end"] = os.getloadavg()
    json.dump(results, open(os.path.join(args.out, "results_max_error.json"), "w"), indent=1)
    print(f"date {results['date']}, {results['machine']}, load average {results['load_average'][0]:.2f} (start) "
          f"{results['load_average_end'][0]:.2f} (end)")
    for name, r in results["inputs"].items():
        print(f"\n{name}: {r['file']} {r['dims']} {r['dtype']}, {r['voxels']} voxels, raw {r['raw_bytes']} bytes\n")
        zstd = next(x["bytes"] for x in r["rows"] if x["coder"] == "zstd -19")
        print("| coder | bytes | bpv | x zstd -19 | PSNR dB | max error (export) | encode s | decode s | ZFP bpv at this PSNR |")
        print("|---|---|---|---|---|---|---|---|---|")
        for x in r["rows"]:
            psnr = f"{x['psnr_db']:.2f}" if "psnr_db" in x else "lossless"
            mx = f"{x.get('max_check', x.get('max', 0)):.4g}"
            if x.get("lossless_check"):
                mx += " (bit-exact)"
            enc = f"{x['encode_s']:.2f}" + (f" (build {x['build_s']:.1f})" if "build_s" in x else "")
            dec = f"{x['decode_s']:.2f}" if "decode_s" in x else ""
            z = x.get("zfp_bpv_equal_psnr")
            eq = (f"{z:.3f} (mlfe {x['bpv'] / z:.2f}x)" if z else "outside ZFP's range") \
                if x["coder"].startswith("mlfe") else ""
            print(f"| {x['coder']} | {x['bytes']} | {x['bpv']:.3f} | {x['bytes'] / zstd:.3f} | {psnr} | {mx} | {enc} | "
                  f"{dec} | {eq} |")


if __name__ == "__main__":
    main()
