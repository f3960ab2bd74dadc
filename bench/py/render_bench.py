#!/usr/bin/python3
"""render_bench.py: ray casting of mlfe hierarchies against a voxel ray caster and VTK (#15).

For every volume and vertex budget (the reduction) it:
  * builds the hierarchy once (`mlfe build VOL --max-vertices N`, not timed here);
  * renders 500x500 (bench default) with `mlfe render H.mlfeh` (mesh: face-to-face, exact
    pre-integration, empty-space skipping) and `mlfe render VOL --reference` (trilinear voxels,
    2 samples per voxel, no skipping), same camera and transfer function, each in its own
    process: render time as the command reports it (best of --repeat), peak RSS of the process;
  * PSNR of the mesh image against the reference image (RGBA premultiplied, peak 1);
  * VTK 9 (python3-vtk9) in separate processes under Xvfb (VTK's mappers need an OpenGL render
    window even when they ray cast on the CPU): vtkFixedPointVolumeRayCastMapper on the voxel
    grid at the VTK default sample distance (1 world unit) and at half a voxel, and
    vtkUnstructuredGridVolumeRayCastMapper (Bunyk) and vtkProjectedTetrahedraMapper (cell
    projection; OpenGL, here Mesa's software llvmpipe under Xvfb, no GPU) on the same leaf
    tetrahedra (exported to .vtu); same camera (orthographic) and transfer function; time of
    the best of the renders after the first (which builds VTK's structures; 2 for the
    tetrahedral mappers, --repeat for the grid), peak RSS of the process and its RSS
    before rendering.
Threads: mlfe and VTK SMP limited to 2 (the machine has 2 cores).

usage: bench/py/render_bench.py [--build DIR] [--work DIR] [--size WxH] [--repeat N] [VOL:TF:verts1,verts2 ...]
"""
import argparse
import json
import os
import re
import resource
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
DATA = os.path.join(ROOT, "..", "shared", "data")

VTK_CHILD = r'''
import json, resource, sys, time
import numpy as np
import vtk
from vtk.util import numpy_support
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_paths import mlfe_binary  # noqa: E402
cfg = json.loads(sys.argv[1])
s = json.loads(open(cfg["setup"]).read())
kind = cfg["kind"]
vtk.vtkMultiThreader.SetGlobalMaximumNumberOfThreads(2)
if kind in ("bunyk", "pt"):
    r = vtk.vtkXMLUnstructuredGridReader(); r.SetFileName(cfg["vtu"]); r.Update()
    data = r.GetOutput(); data.GetPointData().SetActiveScalars("u")
    mapper = vtk.vtkUnstructuredGridVolumeRayCastMapper() if kind == "bunyk" else vtk.vtkProjectedTetrahedraMapper()
    mapper.SetInputData(data)
else:
    nx, ny, nz = s["dims"]
    a = np.fromfile(cfg["raw"], dtype=np.float32)
    img = vtk.vtkImageData(); img.SetDimensions(nx, ny, nz); img.SetSpacing(*s["spacing"]); img.SetOrigin(0, 0, 0)
    arr = numpy_support.numpy_to_vtk(a, deep=1); arr.SetName("f"); img.GetPointData().SetScalars(arr)
    mapper = vtk.vtkFixedPointVolumeRayCastMapper(); mapper.SetInputData(img)
    mapper.SetAutoAdjustSampleDistances(0)
    mapper.SetSampleDistance(cfg["sample_distance"])
    mapper.SetNumberOfThreads(2)
ctf = vtk.vtkColorTransferFunction()
for x, r_, g, b in s["tf"]["rgb"]: ctf.AddRGBPoint(x, r_, g, b)
otf = vtk.vtkPiecewiseFunction()
for x, o in s["tf"]["opacity"]: otf.AddPoint(x, o)
prop = vtk.vtkVolumeProperty(); prop.SetColor(ctf); prop.SetScalarOpacity(otf)
prop.SetScalarOpacityUnitDistance(s["tf"]["unit"]); prop.SetInterpolationTypeToLinear(); prop.ShadeOff()
vol = vtk.vtkVolume(); vol.SetMapper(mapper); vol.SetProperty(prop)
ren = vtk.vtkRenderer(); ren.AddVolume(vol); ren.SetBackground(0, 0, 0)
win = vtk.vtkRenderWindow(); win.SetOffScreenRendering(1); win.AddRenderer(ren); win.SetSize(*cfg["size"])
cam = ren.GetActiveCamera(); c = s["camera"]
cam.SetPosition(*c["position"]); cam.SetFocalPoint(*c["focal_point"]); cam.SetViewUp(*c["view_up"])
cam.ParallelProjectionOn(); cam.SetParallelScale(c["parallel_scale"]); ren.ResetCameraClippingRange()
rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
t0 = time.perf_counter(); win.Render(); first = time.perf_counter() - t0
times = []
for _ in range(cfg["repeat"]):
    vol.Modified(); cam.Modified()
    t0 = time.perf_counter(); win.Render(); times.append(time.perf_counter() - t0)
w2i = vtk.vtkWindowToImageFilter(); w2i.SetInput(win); w2i.Update()
png = vtk.vtkPNGWriter(); png.SetFileName(cfg["png"]); png.SetInputConnection(w2i.GetOutputPort()); png.Write()
print(json.dumps({"first_s": first, "render_s": min(times), "rss_before_mb": rss_before,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}))
'''


def mlfe_render(mlfe, args, repeat):
    """Best render time over `repeat` runs (as `mlfe render` reports it: the render alone, after
    loading), the largest peak RSS of those processes (MiB) and the renderer's counters."""
    best, rss, stats = 1e9, 0.0, ""
    for _ in range(repeat):
        p = subprocess.Popen([mlfe, "--threads", "2"] + args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        _, status, ru = os.wait4(p.pid, 0)
        err = p.stderr.read().decode()
        p.stderr.close()
        p.returncode = status
        if status != 0:
            raise RuntimeError("mlfe %s failed: %s" % (" ".join(args), err[-2000:]))
        rss = max(rss, ru.ru_maxrss / 1024.0)
        m = re.search(r"in ([0-9.]+) s, (.*) ->", err)
        t = float(m.group(1))
        if t < best:
            best, stats = t, m.group(2)
    return best, rss, stats


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--work", default="/tmp/mlfe_render_bench")
    ap.add_argument("--size", default="500x500")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-vtk", action="store_true")
    ap.add_argument("--azimuth", default="30")
    ap.add_argument("--elevation", default="20")
    ap.add_argument("jobs", nargs="*")
    a = ap.parse_args()
    jobs = a.jobs or [os.path.join(DATA, "ct_skull_64.nrrd") + ":bone:8000,35000",
                      os.path.join(DATA, "mri_colin27_brain.nii.gz") + ":mri:45000,100000,215000"]
    os.makedirs(a.work, exist_ok=True)
    mlfe = mlfe_binary(a.build)
    helper = os.path.join(a.build, "bench", "render_bench")
    w, h = [int(x) for x in a.size.lower().split("x")]
    env = dict(os.environ)
    xvfb = None
    if not a.no_vtk and "DISPLAY" not in env:
        xvfb = subprocess.Popen(["Xvfb", ":87", "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(1.5)
        env["DISPLAY"] = ":87"
    rows = []
    try:
        for job in jobs:
            vol, tf, budgets = job.rsplit(":", 2)
            name = os.path.basename(vol).split(".")[0]
            cam = ["--azimuth", a.azimuth, "--elevation", a.elevation, "--size", a.size, "--tf", tf]
            ref_exr = os.path.join(a.work, name + "_ref.exr")
            t_ref, rss_ref, st_ref = mlfe_render(mlfe, ["render", vol, "--reference", "-o", ref_exr,
                                                        "--png", ref_exr[:-4] + ".png"] + cam, a.repeat)
            vtk_grid = {}
            for budget in budgets.split(","):
                tag = "%s_v%s" % (name, budget)
                H = os.path.join(a.work, tag + ".mlfeh")
                if not os.path.exists(H):
                    subprocess.run([mlfe, "--threads", "2", "build", vol, "-o", H, "--max-vertices", budget, "--quiet"], check=True)
                exr = os.path.join(a.work, tag + ".exr")
                t_mesh, rss_mesh, st_mesh = mlfe_render(mlfe, ["render", H, "-o", exr, "--png", exr[:-4] + ".png"] + cam,
                                                        a.repeat)
                ps = json.loads(subprocess.run([helper, "psnr", exr, ref_exr], capture_output=True, text=True,
                                               check=True).stdout)
                prefix = os.path.join(a.work, tag)
                setup = json.loads(subprocess.run([helper, "setup", vol, H, a.azimuth, a.elevation, str(w), str(h), tf,
                                                   prefix], capture_output=True, text=True, check=True).stdout)
                setup_path = prefix + "_setup.json"
                with open(setup_path, "w") as f:
                    json.dump(setup, f)
                row = {"volume": name, "max_vertices": int(budget), "voxels": setup["voxels"], "tets": setup["tets"],
                       "mesh_s": t_mesh, "mesh_rss_mb": rss_mesh, "mesh_stats": st_mesh,
                       "ref_s": t_ref, "ref_rss_mb": rss_ref, "psnr_db": ps["psnr_db"], "max_abs": ps["max_abs"]}
                if not a.no_vtk:
                    def vtk_run(kind, **kw):
                        cfg = dict(kind=kind, setup=setup_path, size=[w, h], repeat=2 if kind in ("bunyk", "pt") else a.repeat,
                                   png=prefix + "_vtk_" + kind + ".png", **kw)
                        e2 = dict(env, OMP_NUM_THREADS="2")
                        p = subprocess.run([sys.executable, "-c", VTK_CHILD, json.dumps(cfg)], capture_output=True,
                                           text=True, env=e2)
                        if p.returncode != 0:
                            return {"error": p.stderr.strip().splitlines()[-1] if p.stderr.strip() else "failed"}
                        return json.loads(p.stdout.strip().splitlines()[-1])
                    if not vtk_grid:
                        sp = min(setup["spacing"])
                        vtk_grid["default"] = vtk_run("fixed", raw=prefix + ".raw", sample_distance=1.0)
                        vtk_grid["half"] = vtk_run("fixed", raw=prefix + ".raw", sample_distance=0.5 * sp)
                    row["vtk_fixed_default"] = vtk_grid["default"]
                    row["vtk_fixed_half_voxel"] = vtk_grid["half"]
                    row["vtk_bunyk"] = vtk_run("bunyk", vtu=prefix + ".vtu")
                    row["vtk_projected_tetrahedra"] = vtk_run("pt", vtu=prefix + ".vtu")
                rows.append(row)
                print(json.dumps(row), flush=True)
    finally:
        if xvfb:
            xvfb.terminate()
            xvfb.wait()
    with open(os.path.join(a.work, "results.json"), "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
