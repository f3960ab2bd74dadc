#!/usr/bin/python3
"""convert_time_bench.py MLFE PEERDIR REPS VOL:ISO...: issue 39's time target, alternated runs in one process.

For each volume, REPS times: the peer (VTK NIfTI read + vtkFlyingEdges3D on 1 thread, in this process, then
meshoptimizer 1.2 simplifyWithUpdate to 10 % of the marching-cubes triangles: PEERDIR/meshopt_update, built by
scripts/build_bench_peers.sh; its own simplify seconds, PLY read excluded), then `MLFE --threads 1|2 convert VOL
--iso ISO -o X.glb` (defaults), CPU and wall seconds. One line per run with the 1-minute load average; quality
figures are convert_bench.py's.
Uses /usr/bin/python3 (python3-vtk9)."""
import os
import resource
import subprocess
import sys
import time

import vtk

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import convert_bench as cb  # noqa: E402
import iso_bench as ib  # noqa: E402

mlfe, peers, reps = sys.argv[1], sys.argv[2], int(sys.argv[3])
WORK = os.path.join(os.environ.get("TMPDIR", "/tmp"), "convert_time_bench")
os.makedirs(WORK, exist_ok=True)
vtk.vtkSMPTools.Initialize(1)


def W(name):
    return os.path.join(WORK, name)


def load():
    return os.getloadavg()[0]


def child_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def peer(vol, iso):
    c0, t0 = time.process_time(), time.perf_counter()
    r = vtk.vtkNIFTIImageReader()
    r.SetFileName(vol)
    r.Update()
    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputConnection(r.GetOutputPort())
    fe.SetValue(0, iso)
    fe.ComputeNormalsOff()
    fe.Update()
    mc_tris = fe.GetOutput().GetNumberOfPolys()  # FE and MC give the same triangles on the lattice
    c_fe, t_fe = time.process_time() - c0, time.perf_counter() - t0
    ib.write_ply(fe.GetOutput(), W("fe.ply"))
    row = cb.meshopt_update_row(f"{peers}/meshopt_update", W, mc_tris, t_fe)
    return dict(cpu_fe=c_fe, wall_fe=t_fe, simplify=row["seconds"] - t_fe, tris=row["triangles"])


def mlfe_run(vol, iso, threads):
    k0, t0 = child_cpu(), time.perf_counter()
    subprocess.run([mlfe, "--threads", str(threads), "convert", vol, "--iso", str(iso), "-o",
                    W(f"m{threads}.glb")], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return dict(cpu=child_cpu() - k0, wall=time.perf_counter() - t0)


for case in sys.argv[4:]:
    vol, iso = case.rsplit(":", 1)
    iso = float(iso)
    for rep in range(reps):
        l = load()
        p = peer(vol, iso)
        print(f"{os.path.basename(vol)} peer load {l:.1f}: FE cpu {p['cpu_fe']:.2f} wall {p['wall_fe']:.2f}; "
              f"simplifyWithUpdate {p['simplify']:.2f} s; {p['tris']} tris; core cpu "
              f"{p['cpu_fe'] + p['simplify']:.2f}", flush=True)
        for th in (1, 2):
            l = load()
            m = mlfe_run(vol, iso, th)
            print(f"{os.path.basename(vol)} mlfe t{th} load {l:.1f}: cpu {m['cpu']:.2f} wall {m['wall']:.2f}",
                  flush=True)
