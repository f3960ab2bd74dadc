#!/usr/bin/python3
"""surface_components.py: how many small pieces a volume's iso-surface has, and how far they lie
from its big ones (the Hausdorff floor of any method that drops them).

usage: bench/py/surface_components.py VOLUME.nii.gz ISO [--small 8] [--big 64]
VTK flying edges on the volume (as convert_bench's reference), vtkPolyDataConnectivityFilter for
the components; distances from each small component's centroid to the nearest vertex of a big
one, in voxels of a 1 mm grid (index coordinates). Uses /usr/bin/python3 with python3-vtk9 and
python3-scipy (scripts/install_bench_deps.sh).
"""
import argparse

import numpy as np
import vtk
from scipy.spatial import cKDTree
from vtk.util.numpy_support import vtk_to_numpy


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("volume")
    ap.add_argument("iso", type=float)
    ap.add_argument("--small", type=int, default=8, help="components of at most this many triangles")
    ap.add_argument("--big", type=int, default=64, help="components of more than this many triangles")
    args = ap.parse_args()
    r = vtk.vtkNIFTIImageReader()
    r.SetFileName(args.volume)
    r.Update()
    img = r.GetOutput()
    img.SetSpacing(1, 1, 1)  # distances in voxels
    img.SetOrigin(0, 0, 0)
    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputData(img)
    fe.SetValue(0, args.iso)
    fe.ComputeNormalsOff()
    fe.Update()
    c = vtk.vtkPolyDataConnectivityFilter()
    c.SetInputData(fe.GetOutput())
    c.SetExtractionModeToAllRegions()
    c.ColorRegionsOn()
    c.Update()
    out = c.GetOutput()
    pts = vtk_to_numpy(out.GetPoints().GetData())
    reg = vtk_to_numpy(out.GetPointData().GetArray("RegionId"))
    sizes = vtk_to_numpy(c.GetRegionSizes())
    small = np.where(sizes <= args.small)[0]
    big = np.where(sizes > args.big)[0]
    print(f"triangles {fe.GetOutput().GetNumberOfPolys()}, components {len(sizes)}, "
          f"with <= {args.small} triangles {len(small)}, with > {args.big} triangles {len(big)}")
    if len(small) == 0 or len(big) == 0:
        return
    order = np.argsort(reg, kind="stable")
    starts = np.searchsorted(reg[order], small)
    ends = np.searchsorted(reg[order], small, side="right")
    cent = np.array([pts[order[s:e]].mean(axis=0) for s, e in zip(starts, ends)])
    d, _ = cKDTree(pts[np.isin(reg, big)]).query(cent)
    for t in (1, 2, 3, 5, 8):
        print(f"small components farther than {t} voxels from every big one: {(d > t).sum()}")
    print(f"farthest: {d.max():.2f} voxels")


if __name__ == "__main__":
    main()
