#!/usr/bin/python3
"""unstructured_render_bench.py: `mlfe render mesh.vtu` against VTK's tetrahedral ray casters (#27).

The paper's Poisson example as an unstructured mesh (bench/data/make_poisson_vtu.py: the unit cube
as n^3 cubes of 6 Kuhn tetrahedra without the column x, y > 0.5, non-convex), rendered as it is
(the mesh is its own finest level; rays enter and re-enter through its boundary faces) by

  * `mlfe --threads 2 render mesh.vtu -o x.exr` (face to face, exact pre-integration):
    per frame = the render time the command prints (after reading and the render structures);
  * VTK 9's vtkUnstructuredGridVolumeRayCastMapper (Bunyk, Kaufman & Silva 1997; 2 threads)
    and vtkUnstructuredGridVolumeZSweepMapper (Farias et al. 2000), each in its own process
    with an off-screen render window (under Xvfb when there is no DISPLAY): per frame = the
    best of --vtk-repeat renders after the first (which builds VTK's structures);

with the same orthographic camera (mlfe's orbit camera: --azimuth, --elevation, framing the
mesh's bounding ball), image size and transfer function (a ParaView JSON colour map for mlfe, the
same points in VTK's colour and opacity functions, the same opacity unit distance), rounds
interleaved (mlfe, Bunyk, ZSweep, mlfe, ...), minimum per renderer. Reported: per-frame times,
the ratios VTK / mlfe, and the mean absolute difference of mlfe's image against each VTK image
(linear RGB in [0, 1]; mlfe's sRGB PNG decoded, VTK's frame buffer read back), as a check that
they render the same thing. The machine may be shared: compare ratios within one run.

usage: bench/py/unstructured_render_bench.py [--n 32,64] [--size 500x500] [--rounds 3]
       [--vtk-repeat 3] [--azimuth 225] [--elevation 25] [--build DIR] [--work DIR] [--json OUT]
"""
import argparse
import json
import math
import os
import re
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))

# The transfer function: "hot"-like colours over the solution's range [0, u_max], opacity from
# 0.02 to 0.3 per 0.1 length units, so most rays cross the whole mesh (no early termination).
TF_UNIT = 0.1


def tf_points(u_max):
    rgb = [(0.0, 0, 0, 0), (0.4 * u_max, 1, 0, 0), (0.8 * u_max, 1, 1, 0), (u_max, 1, 1, 1)]
    opacity = [(0.0, 0.02), (u_max, 0.3)]
    return rgb, opacity


VTK_CHILD = r'''
import json, sys, time
import vtk
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_paths import mlfe_binary  # noqa: E402
cfg = json.loads(sys.argv[1])
vtk.vtkMultiThreader.SetGlobalMaximumNumberOfThreads(2)
r = vtk.vtkXMLUnstructuredGridReader(); r.SetFileName(cfg["vtu"]); r.Update()
data = r.GetOutput(); data.GetPointData().SetActiveScalars("u")
if cfg["kind"] == "bunyk":
    mapper = vtk.vtkUnstructuredGridVolumeRayCastMapper(); mapper.SetNumberOfThreads(2)
else:
    mapper = vtk.vtkUnstructuredGridVolumeZSweepMapper()
mapper.SetInputData(data)
ctf = vtk.vtkColorTransferFunction()
for x, r_, g, b in cfg["rgb"]: ctf.AddRGBPoint(x, r_, g, b)
otf = vtk.vtkPiecewiseFunction()
for x, o in cfg["opacity"]: otf.AddPoint(x, o)
prop = vtk.vtkVolumeProperty(); prop.SetColor(ctf); prop.SetScalarOpacity(otf)
prop.SetScalarOpacityUnitDistance(cfg["unit"]); prop.SetInterpolationTypeToLinear(); prop.ShadeOff()
vol = vtk.vtkVolume(); vol.SetMapper(mapper); vol.SetProperty(prop)
ren = vtk.vtkRenderer(); ren.AddVolume(vol); ren.SetBackground(0, 0, 0)
win = vtk.vtkRenderWindow(); win.SetOffScreenRendering(1); win.AddRenderer(ren); win.SetSize(*cfg["size"])
cam = ren.GetActiveCamera(); c = cfg["camera"]
cam.SetPosition(*c["position"]); cam.SetFocalPoint(*c["focal_point"]); cam.SetViewUp(*c["view_up"])
cam.ParallelProjectionOn(); cam.SetParallelScale(c["parallel_scale"]); ren.ResetCameraClippingRange()
t0 = time.perf_counter(); win.Render(); first = time.perf_counter() - t0
times = []
for _ in range(cfg["repeat"]):
    cam.Modified()
    t0 = time.perf_counter(); win.Render(); times.append(time.perf_counter() - t0)
w2i = vtk.vtkWindowToImageFilter(); w2i.SetInput(win); w2i.Update()
png = vtk.vtkPNGWriter(); png.SetFileName(cfg["png"]); png.SetInputConnection(w2i.GetOutputPort()); png.Write()
print(json.dumps({"first_s": first, "frame_s": min(times), "frames_s": times}))
'''


def orbit_camera(center, radius, az_deg, el_deg, width, height):
    """mlfe's orbit_camera (core/render/volume_render.cpp), orthographic, as VTK camera settings."""
    az, el = math.radians(az_deg), math.radians(el_deg)
    back = (math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el))
    aspect = width / height
    fit = 1.05 * radius * max(1.0, 1.0 / aspect)
    dist = 3.0 * radius
    return {"position": [center[i] + dist * back[i] for i in range(3)], "focal_point": list(center),
            "view_up": [0, 0, 1], "parallel_scale": fit}


def mesh_facts(vtu):
    import vtk
    from vtk.util import numpy_support as ns
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(vtu)
    r.Update()
    g = r.GetOutput()
    lo_hi = g.GetBounds()
    u = ns.vtk_to_numpy(g.GetPointData().GetArray("u"))
    return {"tets": g.GetNumberOfCells(), "points": g.GetNumberOfPoints(), "bounds": lo_hi,
            "u_min": float(u.min()), "u_max": float(u.max())}


def run_mlfe(mlfe, args):
    p = subprocess.run([mlfe, "--threads", "2"] + args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        raise RuntimeError("mlfe %s failed: %s" % (" ".join(args), p.stderr[-2000:]))
    m = re.search(r"in ([0-9.]+) s, (.*) ->", p.stderr)
    return float(m.group(1)), m.group(2)


def read_png_linear(path, srgb):
    """RGB in [0, 1], sRGB decoded when `srgb` (mlfe's preview; VTK's frame buffer is linear)."""
    import vtk
    from vtk.util import numpy_support as ns
    r = vtk.vtkPNGReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    w, h, _ = img.GetDimensions()
    # Both files are written top row first and the reader turns both the same way.
    a = ns.vtk_to_numpy(img.GetPointData().GetScalars()).reshape(h, w, -1)[:, :, :3] / 255.0
    if srgb:
        a = a.copy()
        lo = a <= 0.04045
        a[lo] = a[lo] / 12.92
        a[~lo] = ((a[~lo] + 0.055) / 1.055) ** 2.4
    return a


def mean_abs_diff(a, b):
    import numpy as np
    return float(np.mean(np.abs(np.asarray(a) - np.asarray(b))))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", default="32,64", help="Poisson meshes: cubes per axis (6 n^3 * 3/4 tetrahedra)")
    ap.add_argument("--size", default="500x500")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--vtk-repeat", type=int, default=3)
    ap.add_argument("--azimuth", type=float, default=225)
    ap.add_argument("--elevation", type=float, default=25)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--work", default="/tmp/mlfe_unstructured_bench")
    ap.add_argument("--json")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    mlfe = mlfe_binary(a.build)
    w, h = [int(x) for x in a.size.lower().split("x")]
    env = dict(os.environ)
    xvfb = None
    if "DISPLAY" not in env:
        xvfb = subprocess.Popen(["Xvfb", ":91", "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(1.5)
        env["DISPLAY"] = ":91"
    rows = []
    try:
        for n in [int(x) for x in a.n.split(",")]:
            vtu = os.path.join(a.work, "poisson_n%d.vtu" % n)
            if not os.path.exists(vtu):
                subprocess.run([sys.executable, os.path.join(HERE, "..", "data", "make_poisson_vtu.py"), vtu, "--n", str(n)],
                               check=True, stdout=subprocess.DEVNULL)
            facts = mesh_facts(vtu)
            b = facts["bounds"]
            lo, hi = (b[0], b[2], b[4]), (b[1], b[3], b[5])
            center = [0.5 * (lo[i] + hi[i]) for i in range(3)]
            radius = 0.5 * math.sqrt(sum((hi[i] - lo[i]) ** 2 for i in range(3)))
            cam = orbit_camera(center, radius, a.azimuth, a.elevation, w, h)
            rgb, opacity = tf_points(facts["u_max"])
            tf_json = os.path.join(a.work, "tf.json")
            with open(tf_json, "w") as f:
                json.dump([{"Name": "hot-ish", "RGBPoints": [v for p in rgb for v in p],
                            "Points": [v for x, o in opacity for v in (x, o, 0.5, 0.0)]}], f)
            exr = os.path.join(a.work, "mlfe_n%d.exr" % n)
            mlfe_args = ["render", vtu, "-o", exr, "--png", exr[:-4] + ".png", "--tf", tf_json, "--tf-unit",
                         str(TF_UNIT), "--size", a.size, "--azimuth", str(a.azimuth), "--elevation", str(a.elevation)]
            best = {"mlfe": 1e9, "bunyk": 1e9, "zsweep": 1e9}
            first = {}
            stats = ""
            for _ in range(a.rounds):
                t, st = run_mlfe(mlfe, mlfe_args)
                if t < best["mlfe"]:
                    best["mlfe"], stats = t, st
                for kind in ("bunyk", "zsweep"):
                    cfg = {"kind": kind, "vtu": vtu, "size": [w, h], "repeat": a.vtk_repeat, "camera": cam,
                           "rgb": rgb, "opacity": opacity, "unit": TF_UNIT,
                           "png": os.path.join(a.work, "vtk_%s_n%d.png" % (kind, n))}
                    p = subprocess.run([sys.executable, "-c", VTK_CHILD, json.dumps(cfg)], capture_output=True,
                                       text=True, env=env)
                    if p.returncode != 0:
                        raise RuntimeError("VTK %s failed: %s" % (kind, p.stderr[-2000:]))
                    res = json.loads(p.stdout.strip().splitlines()[-1])
                    best[kind] = min(best[kind], res["frame_s"])
                    first[kind] = min(first.get(kind, 1e9), res["first_s"])
            # Images: mlfe's PNG (sRGB over black, row 0 at the top) and VTK's frame buffer.
            mine = read_png_linear(exr[:-4] + ".png", True)
            diffs = {}
            for kind in ("bunyk", "zsweep"):
                theirs = read_png_linear(os.path.join(a.work, "vtk_%s_n%d.png" % (kind, n)), False)
                diffs[kind] = mean_abs_diff(mine, theirs)
            row = {"n": n, "tets": facts["tets"], "points": facts["points"], "size": a.size,
                   "mlfe_frame_s": best["mlfe"], "mlfe_stats": stats,
                   "bunyk_frame_s": best["bunyk"], "bunyk_first_s": first["bunyk"],
                   "zsweep_frame_s": best["zsweep"], "zsweep_first_s": first["zsweep"],
                   "bunyk_over_mlfe": best["bunyk"] / best["mlfe"], "zsweep_over_mlfe": best["zsweep"] / best["mlfe"],
                   "mean_abs_rgb_diff_vs_bunyk": diffs["bunyk"], "mean_abs_rgb_diff_vs_zsweep": diffs["zsweep"],
                   "load_average": os.getloadavg()}
            rows.append(row)
            print(json.dumps(row), flush=True)
    finally:
        if xvfb:
            xvfb.terminate()
            xvfb.wait()
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
