#!/usr/bin/env python3
"""The hierarchy file (`mlfe build`, .mlfeh) against the scientific and medical compressors on one
volume (issue #44): at equal PSNR, at equal maximum error, and lossless, all peers in the same run.

Figures per row: bytes, bits per voxel, PSNR, maximum absolute error, encode and decode seconds.
PSNR is SZ3's definition, over the input's value range:
    PSNR = 20 log10(max(x) - min(x)) - 10 log10(MSE),  MSE = mean((x - x')^2)
with x' the decoded values as the decoder gives them (floats for mlfe, SZ3, SPERR, ZFP; not
rounded back to the input's integer type). Seconds are CPU seconds (user + system), because the
machines are shared and a loaded machine stretches wall time: of the command for mlfe, sz3,
sperr3d, cjxl/djxl and zstd (reading and writing their files included; mlfe's decode is `mlfe
export H -o X.raw`, which rebuilds and resamples the whole grid), of this process for ZFP (zfpy),
of the coding alone for JPEG-LS (printed by the tool). Every method runs on one thread (mlfe
--threads 1; SZ3 and SPERR built without OpenMP), so CPU seconds are the single-core time; the
wall times are in the JSON.

Modes (--modes, default all three):
  psnr      for each target (--targets, default 43.5,37 dB) each method's setting is found by
            bisection on its parameter (log2 of the bound; SPERR: its --psnr target) until the PSNR
            is within --tol dB (default 0.1) or --steps runs; the row is the run nearest the target,
            and "bytes at target" interpolates log(bytes) linearly in PSNR between the nearest runs
            on either side. Methods: mlfe --max-error, mlfe --rms (each --mlfe binary), SZ3 ABS,
            SPERR --psnr, ZFP accuracy.
  maxerror  every sample within E, for E in --bounds (default 1,2,4 data units): mlfe --max-error,
            SZ3 ABS, SPERR --pwe, ZFP accuracy, JPEG-LS near-lossless NEAR=E (integer E, integer data).
  lossless  mlfe --max-error 0, zstd -19 of the raw voxels, JPEG-LS per z slice, JPEG XL lossless
            (-d 0, effort 7) of one 2D mosaic of the z slices, SZ3 ABS 0 (its lossless path);
            each checked bit for bit. SPERR has no lossless mode.

Peers in --peers (default build/bench-peers): jpegls_slices (bench/cpp/peers/, CharLS; built by
scripts/build_bench_peers.sh), sz3 (SZ3 v3.3.2's tools/sz3) and sperr3d (SPERR v0.8.5), the last
two built by hand from their release sources without OpenMP (this repository carries no recipe for
them); cjxl/djxl (libjxl-tools) and zstd on PATH; python3-zfpy (scripts/install_bench_deps.sh). A
missing peer is skipped and named in the output.

Usage: /usr/bin/python3 bench/py/file_bench.py VOLUME [--mlfe PATH[=LABEL] ...] [--modes psnr,maxerror,lossless]
           [--methods mlfe-maxerr,mlfe-rms,sz3,sperr,zfp,jpegls,jxl,zstd] [--mlfe-args "..."] [--out DIR]
VOLUME: NIfTI (.nii, .nii.gz), NRRD, or raw with a .raw.json beside it ({"dims", "dtype"}).
Prints Markdown tables (with machine, date, load average, command) and writes OUT/<volume>.json.
"""
import argparse
import json
import math
import os
import shlex
import shutil
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import hierarchy_file_bench as hfb  # noqa: E402  (read_voxels, errors, run_mlfe, run_zfp)

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
ALL_METHODS = "mlfe-maxerr,mlfe-rms,sz3,sperr,zfp,jpegls,jxl,zstd"


def read_volume(path):
    """(voxels x fastest, (nx, ny, nz)) from NIfTI/NRRD (VTK) or raw + .raw.json."""
    if path.endswith(".raw"):
        meta = json.load(open(path + ".json"))
        dims = tuple(meta["dims"])
        dtype = np.dtype(meta["dtype"]).newbyteorder("<" if meta.get("endian", "little") == "little" else ">")
        return np.fromfile(path, dtype=dtype).astype(dtype.newbyteorder("=")), dims
    return hfb.read_voxels(path)


def timed(cmd):
    """(CPU seconds, stdout) of the command."""
    cpu = hfb.child_cpu_s()
    p = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return hfb.child_cpu_s() - cpu, p.stdout


class Bench:
    """One volume, its float32 copy on disk for the float peers, and the rows measured."""

    def __init__(self, args, path):
        self.args = args
        self.path = os.path.abspath(path)
        self.vox, self.dims = read_volume(path)
        self.n = self.vox.size
        self.peak = float(self.vox.max()) - float(self.vox.min())
        self.integer = self.vox.dtype.kind in "iu"
        self.tmp = os.path.join(args.out, os.path.basename(path).split(".")[0])
        os.makedirs(self.tmp, exist_ok=True)
        self.f32 = os.path.join(self.tmp, "input.f32")
        self.vox.astype(np.float32).tofile(self.f32)
        self.mlfe_runs = {}  # (binary, options) -> row: E = 2, 4 of the max-error table often ran in the bisection

    def measured(self, method, setting, nbytes, enc, dec, decoded, **extra):
        row = {"method": method, "setting": setting, "bytes": nbytes, "bpv": 8 * nbytes / self.n,
               "encode_s": enc, "decode_s": dec}
        if decoded is not None:
            e = hfb.errors(decoded.ravel(), self.vox.ravel(), self.peak)
            row.update(psnr_db=e["psnr_db"], max=e["max"], exact=bool(e["max"] == 0))
        row.update(extra)
        return row

    # -- the methods: each takes its parameter and returns a row ------------------------------
    def mlfe(self, binary, label, opts):
        key = (binary, tuple(opts))
        if key not in self.mlfe_runs:
            self.mlfe_runs[key] = self.run_mlfe(binary, label, opts)
        return dict(self.mlfe_runs[key])

    def run_mlfe(self, binary, label, opts):
        tag = f"mlfe_{abs(hash((binary, tuple(opts)))):x}"
        r = hfb.run_mlfe(binary, self.path, opts + ["--quiet"] + shlex.split(self.args.mlfe_args), self.tmp, tag,
                         self.n, global_opts=["--threads", "1"])
        for f in (tag + ".mlfeh", tag + ".json"):
            os.remove(os.path.join(self.tmp, f))
        return self.measured(label, " ".join(opts), int(r["bytes"]), r["build_cpu_s"], r["decode_cpu_s"],
                             r["decoded"], encode_wall_s=r["build_s"], decode_wall_s=r["decode_s"])

    def sz3(self, bound):
        z, o = self.f32 + ".sz", self.f32 + ".sz.out"
        nx, ny, nz = (str(d) for d in self.dims)
        enc, _ = timed([self.args.sz3, "-f", "-i", self.f32, "-z", z, "-3", nx, ny, nz, "-M", "ABS", f"{bound:.9g}"])
        dec, _ = timed([self.args.sz3, "-f", "-z", z, "-o", o, "-3", nx, ny, nz, "-M", "ABS", f"{bound:.9g}"])
        row = self.measured("SZ3 3.3.2", f"-M ABS {bound:.4g}", os.path.getsize(z), enc, dec,
                            np.fromfile(o, dtype=np.float32))
        os.remove(z), os.remove(o)
        return row

    def sperr(self, opt, value):
        z, o = self.f32 + ".sperr", self.f32 + ".sperr.out"
        enc, _ = timed([self.args.sperr, "-c", "--ftype", "32", "--dims", *(str(d) for d in self.dims),
                        opt, f"{value:.9g}", "--bitstream", z, self.f32])
        dec, _ = timed([self.args.sperr, "-d", "--decomp_f", o, z])
        row = self.measured("SPERR 0.8.5", f"{opt} {value:.4g}", os.path.getsize(z), enc, dec,
                            np.fromfile(o, dtype=np.float32))
        os.remove(z), os.remove(o)
        return row

    def zfp(self, tol):
        r = hfb.run_zfp(self.vox, self.dims, tol, self.peak, clock=time.process_time)
        return {"method": "ZFP (zfpy)", "setting": f"accuracy {tol:.4g}", "bytes": r["bytes"], "bpv": r["bpv"],
                "encode_s": r["encode_s"], "decode_s": r["decode_s"], "psnr_db": r["psnr_db"], "max": r["max"],
                "exact": r["max"] == 0}

    def jpegls(self, near):
        raw, z, o = os.path.join(self.tmp, "input.raw"), os.path.join(self.tmp, "x.jlss"), os.path.join(self.tmp, "x.out")
        bits = 8 if self.vox.dtype.itemsize == 1 else 16
        self.vox.astype("<u1" if bits == 8 else "<u2").tofile(raw)
        _, out = timed([self.args.jpegls, "encode", raw, *(str(d) for d in self.dims), str(bits), str(near), z])
        _, dout = timed([self.args.jpegls, "decode", z, o])
        d = np.fromfile(o, dtype="<u1" if bits == 8 else "<u2")
        row = self.measured("JPEG-LS (CharLS, per slice)", f"NEAR {near}", os.path.getsize(z),
                            json.loads(out)["encode_s"], json.loads(dout)["decode_s"], d)
        for f in (raw, z, o):
            os.remove(f)
        return row

    def jxl(self):
        """Lossless JPEG XL of one mosaic: the z slices tiled row by row into a near-square 2D
        image (zero padding in the unused tiles), one cjxl call."""
        nx, ny, nz = self.dims
        cols = math.ceil(math.sqrt(nz * ny / nx))
        rows = math.ceil(nz / cols)
        bits = 8 if self.vox.dtype.itemsize == 1 else 16
        slices = np.zeros((rows * cols, ny, nx), dtype=">u1" if bits == 8 else ">u2")
        slices[:nz] = self.vox.reshape(nz, ny, nx)
        mosaic = slices.reshape(rows, cols, ny, nx).transpose(0, 2, 1, 3).reshape(rows * ny, cols * nx)
        pgm, z, o = (os.path.join(self.tmp, f) for f in ("m.pgm", "m.jxl", "m_out.pgm"))
        with open(pgm, "wb") as f:
            f.write(f"P5\n{cols * nx} {rows * ny}\n{255 if bits == 8 else 65535}\n".encode())
            f.write(mosaic.tobytes())
        enc, _ = timed(["cjxl", pgm, z, "-d", "0", "-e", "7", "--num_threads=1"])
        dec, _ = timed(["djxl", z, o, "--num_threads=1"])
        back = np.frombuffer(open(o, "rb").read()[-mosaic.nbytes:], dtype=mosaic.dtype).reshape(mosaic.shape)
        back = back.reshape(rows, ny, cols, nx).transpose(0, 2, 1, 3).reshape(rows * cols, ny, nx)[:nz]
        row = self.measured("JPEG XL (cjxl 0.7)", f"-d 0 -e 7, {cols}x{rows} mosaic", os.path.getsize(z), enc, dec,
                            back.astype(np.float64))
        for f in (pgm, z, o):
            os.remove(f)
        return row

    def zstd(self):
        raw, z, o = (os.path.join(self.tmp, f) for f in ("input.raw", "input.raw.zst", "input.raw.out"))
        self.vox.tofile(raw)
        enc, _ = timed(["zstd", "-19", "-q", "-f", "-T1", raw, "-o", z])
        dec, _ = timed(["zstd", "-d", "-q", "-f", z, "-o", o])
        row = self.measured("zstd -19", "raw voxels", os.path.getsize(z), enc, dec, np.fromfile(o, dtype=self.vox.dtype))
        for f in (raw, z, o):
            os.remove(f)
        return row


def bisect_psnr(run, x0, slope, target, tol, steps, discrete=False):
    """Runs run(x) (PSNR falling as x grows, about `slope` dB per unit of x) from x0 until the PSNR
    is within tol dB of the target or after `steps` runs. The next x is the secant through the
    nearest runs on either side of the target (the slope model before both sides are known),
    kept inside the bracket. discrete: x only integer (a parameter that acts in steps: ZFP's
    tolerance is a power of two, mlfe's --max-error on integer data an integer); the search ends
    when the target lies between adjacent integers. Returns the run nearest the target, with bytes_at_target: log(bytes)
    interpolated linearly in PSNR between the nearest runs on either side."""
    runs = []
    x = x0
    for _ in range(steps):
        if discrete:
            x = round(x)
            if any(x == v for v, _ in runs):
                break
        r = run(x)
        runs.append((x, r))
        print(f"  {r['method']} {r['setting']}: {r['bytes']} B, {r['psnr_db']:.2f} dB", file=sys.stderr)
        if abs(r["psnr_db"] - target) <= tol:
            break
        above = [(x, r) for x, r in runs if r["psnr_db"] > target]
        below = [(x, r) for x, r in runs if r["psnr_db"] < target]
        if above and below:
            (xa, ra), (xb, rb) = max(above, key=lambda v: v[0]), min(below, key=lambda v: v[0])
            pa = min(ra["psnr_db"], target + 60)  # a lossless run has infinite PSNR
            x = xa + (pa - target) / (pa - rb["psnr_db"]) * (xb - xa)
            x = min(max(x, xa + 0.05 * (xb - xa)), xb - 0.05 * (xb - xa))
            if discrete and abs(xb - xa) <= 1:
                break
            if discrete:  # strictly inside the bracket
                x = min(max(round(x), xa + 1), xb - 1)
        else:
            x = x + (target - min(r["psnr_db"], target + 60)) / slope
            if discrete:  # at least one step outward
                x = x + math.copysign(1, x - runs[-1][0]) if round(x) == runs[-1][0] else x
    rows = sorted((r for _, r in runs), key=lambda r: r["psnr_db"])
    best = dict(min(rows, key=lambda r: abs(r["psnr_db"] - target)), runs=len(runs))
    above = [r for r in rows if target <= r["psnr_db"] < math.inf]
    below = [r for r in rows if r["psnr_db"] < target]
    if above and below:
        a, b = above[0], below[-1]
        w = (target - b["psnr_db"]) / (a["psnr_db"] - b["psnr_db"])
        best["bytes_at_target"] = math.exp(math.log(b["bytes"]) + w * (math.log(a["bytes"]) - math.log(b["bytes"])))
    elif abs(best["psnr_db"] - target) <= tol:
        best["bytes_at_target"] = best["bytes"]
    return best


def psnr_rows(b, methods, target):
    """Each method at `target` dB. Starting points from the uniform quantizer of step 2E, whose
    RMS error is E/sqrt(3); x is log2 of the bound (-6.02 dB per unit) except SPERR's (-PSNR)."""
    a = b.args
    rms0 = b.peak * 10 ** (-target / 20)
    e0 = math.log2(rms0 * math.sqrt(3))
    out = []
    for binary, label in a.mlfe:
        if "mlfe-maxerr" in methods and b.integer:  # integer data: E acts as its integer part
            out.append(bisect_psnr(lambda x: b.mlfe(binary, label, ["--max-error", str(max(int(x), 1))]),
                                   2 ** e0, -6.02 / 2 ** e0, target, a.tol, a.steps, discrete=True))
        elif "mlfe-maxerr" in methods:
            out.append(bisect_psnr(lambda x: b.mlfe(binary, label, ["--max-error", f"{2 ** x:.4g}"]), e0, -6.02,
                                   target, a.tol, a.steps))
        if "mlfe-rms" in methods:
            out.append(bisect_psnr(lambda x: b.mlfe(binary, label, ["--rms", f"{2 ** x:.4g}"]), math.log2(rms0),
                                   -6.02, target, a.tol, a.steps))
    if "sz3" in methods:
        out.append(bisect_psnr(lambda x: b.sz3(2 ** x), e0, -6.02, target, a.tol, a.steps))
    if "sperr" in methods:
        out.append(bisect_psnr(lambda x: b.sperr("--psnr", -x), -target, -1, target, a.tol, a.steps))
    if "zfp" in methods:
        out.append(bisect_psnr(lambda x: b.zfp(2 ** x), e0 + 1, -6.02, target, a.tol, a.steps, discrete=True))
    return out


def maxerror_rows(b, methods, e):
    out = []
    for binary, label in b.args.mlfe:
        if "mlfe-maxerr" in methods:
            out.append(b.mlfe(binary, label, ["--max-error", str(int(e)) if b.integer and e == int(e) else f"{e:g}"]))
    if "sz3" in methods:
        out.append(b.sz3(e))
    if "sperr" in methods:
        out.append(b.sperr("--pwe", e))
    if "zfp" in methods:
        out.append(b.zfp(e))
    if "jpegls" in methods and b.integer and e == int(e):
        out.append(b.jpegls(int(e)))
    for r in out:
        r["within_bound"] = r["max"] <= e * (1 + 1e-6)
        print(f"  {r['method']} {r['setting']}: {r['bytes']} B, max {r['max']:.4g}", file=sys.stderr)
    return out


def lossless_rows(b, methods):
    out = []
    for binary, label in b.args.mlfe:
        if methods & {"mlfe-maxerr", "mlfe-rms"}:
            out.append(b.mlfe(binary, label, ["--max-error", "0"]))
    if "zstd" in methods:
        out.append(b.zstd())
    if "jpegls" in methods and b.integer:
        out.append(b.jpegls(0))
    if "jxl" in methods and b.integer and b.vox.min() >= 0:
        out.append(b.jxl())
    if "sz3" in methods:
        out.append(b.sz3(0))
    for r in out:
        print(f"  {r['method']} {r['setting']}: {r['bytes']} B, exact {r['exact']}", file=sys.stderr)
    return out


def available(args, methods):
    """The methods whose tools exist; the others named in the output as skipped."""
    need = {"sz3": args.sz3, "sperr": args.sperr, "jpegls": args.jpegls, "jxl": shutil.which("cjxl"),
            "zstd": shutil.which("zstd"), "zfp": hfb.zfpy}
    skipped = [m for m in methods if m in need and not (need[m] and (not isinstance(need[m], str)
                                                                     or os.path.exists(need[m])))]
    return set(methods) - set(skipped), skipped


def table(title, rows, ref_method="SZ3 3.3.2"):
    """Markdown: one row per method; x SZ3 compares bytes (interpolated to the target when known)."""
    ref = next((r for r in rows if r["method"] == ref_method), None)
    lines = [f"\n{title}\n", "| method | setting | bytes | bits/voxel | PSNR dB | max abs error | encode s (CPU) | "
             "decode s (CPU) | bytes at target | x SZ3 |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        psnr = "lossless" if r.get("exact") else f"{r['psnr_db']:.2f}"
        at = r.get("bytes_at_target")
        size = at or r["bytes"]
        ratio = f"{size / (ref.get('bytes_at_target') or ref['bytes']):.2f}" if ref else ""
        note = "" if r.get("within_bound", True) else " (over E)"
        lines.append(f"| {r['method']} | {r['setting']} | {r['bytes']:,} | {r['bpv']:.3f} | {psnr} | "
                     f"{r['max']:.4g}{note} | {r['encode_s']:.2f} | {r['decode_s']:.2f} | "
                     f"{f'{at:,.0f}' if at else ''} | {ratio} |")
    return "\n".join(lines)


def parse_args():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("volume")
    ap.add_argument("--mlfe", action="append", default=[],
                    help="mlfe binary, optionally PATH=LABEL; repeat to compare builds (default build/.../mlfe)")
    ap.add_argument("--mlfe-args", default="", help="extra `mlfe build` options for every mlfe row")
    ap.add_argument("--peers", default=os.path.join(ROOT, "build", "bench-peers"))
    ap.add_argument("--modes", default="psnr,maxerror,lossless")
    ap.add_argument("--methods", default=ALL_METHODS.replace("mlfe-rms,", ""),
                    help=f"any of {ALL_METHODS} (mlfe-rms: the least-squares build bisected on --rms; off by default)")
    ap.add_argument("--targets", default="43.5,37")
    ap.add_argument("--bounds", default="1,2,4")
    ap.add_argument("--tol", type=float, default=0.1, help="dB from the target that ends the bisection")
    ap.add_argument("--steps", type=int, default=5, help="runs per method and target at most")
    ap.add_argument("--out", default="/tmp/file_bench")
    args = ap.parse_args()
    args.mlfe = [(os.path.abspath(m.split("=")[0]), m.split("=")[1] if "=" in m else "mlfe")
                 for m in args.mlfe or [os.path.join(ROOT, "build", "converters", "cli", "mlfe")]]
    args.sz3 = os.path.join(args.peers, "sz3")
    args.sperr = os.path.join(args.peers, "sperr3d")
    args.jpegls = os.path.join(args.peers, "jpegls_slices")
    return args


def main():
    args = parse_args()
    os.makedirs(args.out, exist_ok=True)
    methods, skipped = available(args, args.methods.split(","))
    b = Bench(args, args.volume)
    res = {"command": " ".join(shlex.quote(a) for a in sys.argv), "machine": f"{os.uname().nodename}, "
           f"{os.cpu_count()} cores", "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
           "load_average": os.getloadavg(), "volume": b.path, "dims": b.dims, "dtype": str(b.vox.dtype),
           "range": b.peak, "skipped": skipped, "modes": {}}
    modes = args.modes.split(",")
    if "psnr" in modes:
        for t in (float(x) for x in args.targets.split(",")):
            print(f"equal PSNR {t} dB", file=sys.stderr)
            res["modes"][f"equal PSNR ~{t:g} dB"] = psnr_rows(b, methods, t)
    if "maxerror" in modes:
        for e in (float(x) for x in args.bounds.split(",")):
            print(f"max error {e:g}", file=sys.stderr)
            res["modes"][f"equal max error E = {e:g}"] = maxerror_rows(b, methods, e)
    if "lossless" in modes:
        print("lossless", file=sys.stderr)
        res["modes"]["lossless"] = lossless_rows(b, methods)
    res["load_average_end"] = os.getloadavg()
    os.remove(b.f32)
    name = os.path.basename(args.volume).split(".")[0]
    json.dump(res, open(os.path.join(args.out, name + ".json"), "w"), indent=1)
    print(f"**{name}**: {b.path}, {b.dims[0]}x{b.dims[1]}x{b.dims[2]} {b.vox.dtype}, value range {b.peak:g}; "
          f"{res['machine']}, {res['date']}, load average {res['load_average'][0]:.1f} (start) "
          f"{res['load_average_end'][0]:.1f} (end)\n\n`{res['command']}`")
    if skipped:
        print(f"\nskipped (tool missing): {', '.join(skipped)}")
    for title, rows in res["modes"].items():
        print(table(f"{name}, {title}:", rows))


if __name__ == "__main__":
    main()
