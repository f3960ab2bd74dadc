#!/usr/bin/env python3
"""The paper's Poisson example as an unstructured input for `mlfe build` (issue #16, item 5).

A cube [0, 1]^3 as n^3 cubes of 6 Kuhn tetrahedra, without the quarter x > 0.5, y > 0.5 (the
re-entrant edge x = y = 0.5, along z), with point values of the L-shape solution
r^(2/3) sin(2θ/3) around that edge (θ = 0 on the face x = 0.5, y > 0.5 and 3π/2 on the face
y = 0.5, x > 0.5, so the function is 0 on both faces of the cut). All lattice points are kept,
the corner's unused ones too. Written with python3-vtk9's XML writer (appended, zlib).

    /usr/bin/python3 bench/data/make_poisson_vtu.py [OUT.vtu] [--n 32]
"""
import argparse
import math

import numpy as np
import vtk
from vtk.util import numpy_support as ns


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out", nargs="?", default="poisson_cut_corner.vtu")
    ap.add_argument("--n", type=int, default=32)
    a = ap.parse_args()
    n = a.n
    idx = lambda i, j, k: i + (n + 1) * (j + (n + 1) * k)
    pts = np.array([[i / n, j / n, k / n] for k in range(n + 1) for j in range(n + 1) for i in range(n + 1)])
    kuhn = [(0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 4, 6, 7)]
    g = vtk.vtkUnstructuredGrid()
    tets = 0
    for k in range(n):
        for j in range(n):
            for i in range(n):
                if i >= n // 2 and j >= n // 2:
                    continue
                c = [idx(i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1)) for b in range(8)]
                for t in kuhn:
                    g.InsertNextCell(vtk.VTK_TETRA, 4, [c[v] for v in t])
                    tets += 1

    def u(p):
        x, y = p[0] - 0.5, p[1] - 0.5
        t = (math.atan2(y, x) - math.pi / 2) % (2 * math.pi)
        return math.hypot(x, y) ** (2 / 3) * math.sin(2 * t / 3)

    vp = vtk.vtkPoints()
    vp.SetData(ns.numpy_to_vtk(pts, deep=1))
    g.SetPoints(vp)
    vals = ns.numpy_to_vtk(np.array([u(p) for p in pts]), deep=1)
    vals.SetName("u")
    g.GetPointData().SetScalars(vals)
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetFileName(a.out)
    w.SetInputData(g)
    if not w.Write():
        raise SystemExit(f"{a.out}: cannot write")
    print(f"{a.out}: {tets} tetrahedra, {len(pts)} points")


if __name__ == "__main__":
    main()
