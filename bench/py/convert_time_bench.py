#!/usr/bin/python3
"""convert_time_bench.py MLFE PEERDIR REPS VOL:ISO...: issue 39's time target, alternated runs in one process.

For each volume, REPS times: the peer (VTK NIfTI read + vtkFlyingEdges3D on 1 thread, in this process, then
meshoptimizer 1.2 simplifyWithUpdate to 10 % of the marching-cubes triangles: PEERDIR/meshopt_update, built by
scripts/build_bench_peers.sh; its own simplify seconds, PLY read excluded), then `MLFE --threads 1|2 convert VOL
--iso ISO -o X.glb` (defaults), CPU and wall seconds. One line per run with the 1-minute load average; quality
figures are convert_bench.py's.
Uses /usr/bin/python3 (python3-vtk9)."""
import json, os, resource, subprocess, sys, time
import vtk

mlfe, peers, reps = sys.argv[1], sys.argv[2], int(sys.argv[3])
W = os.path.join(os.environ.get("TMPDIR", "/tmp"), "convert_time_bench")
os.makedirs(W, exist_ok=True)
vtk.vtkSMPTools.Initialize(1)


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
    w = vtk.vtkPLYWriter()
    w.SetFileName(f"{W}/fe.ply")
    w.SetInputData(fe.GetOutput())
    w.Write()
    k0, t1 = child_cpu(), time.perf_counter()
    out = subprocess.run([f"{peers}/meshopt_update", f"{W}/fe.ply", str(mc_tris // 10), f"{W}/femu.ply"],
                         stdout=subprocess.PIPE, text=True, check=True).stdout
    j = json.loads(out.strip().splitlines()[-1])
    return dict(cpu_fe=c_fe, wall_fe=t_fe, simplify=j["simplify_seconds"], tool_cpu=child_cpu() - k0,
                tool_wall=time.perf_counter() - t1, tris=j["triangles"])


def mlfe_run(vol, iso, threads):
    k0, t0 = child_cpu(), time.perf_counter()
    subprocess.run([mlfe, "--threads", str(threads), "convert", vol, "--iso", str(iso), "-o",
                    f"{W}/m{threads}.glb"], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return dict(cpu=child_cpu() - k0, wall=time.perf_counter() - t0)


for case in sys.argv[4:]:
    vol, iso = case.rsplit(":", 1)
    iso = float(iso)
    for rep in range(reps):
        l = load()
        p = peer(vol, iso)
        print(f"{os.path.basename(vol)} peer load {l:.1f}: FE cpu {p['cpu_fe']:.2f} wall {p['wall_fe']:.2f}; "
              f"simplifyWithUpdate {p['simplify']:.2f} s (tool incl. PLY read: cpu {p['tool_cpu']:.2f} wall "
              f"{p['tool_wall']:.2f}); {p['tris']} tris; core cpu {p['cpu_fe'] + p['simplify']:.2f}", flush=True)
        for th in (1, 2):
            l = load()
            m = mlfe_run(vol, iso, th)
            print(f"{os.path.basename(vol)} mlfe t{th} load {l:.1f}: cpu {m['cpu']:.2f} wall {m['wall']:.2f}",
                  flush=True)
