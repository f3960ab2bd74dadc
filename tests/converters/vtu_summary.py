"""Reads a .vtu with VTK's own XML reader (python3-vtk9) and prints, on one line: cells,
points, tetrahedra, min and max of the point array "u", max of the cell array "level" and the
total cell volume. Used by tests/converters/export_command_test.cpp."""
import sys

from vtkmodules.vtkCommonDataModel import vtkTetra
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

r = vtkXMLUnstructuredGridReader()
r.SetFileName(sys.argv[1])
r.Update()
if r.GetErrorCode() != 0:
    sys.exit("VTK cannot read " + sys.argv[1])
g = r.GetOutput()
tets = sum(1 for i in range(g.GetNumberOfCells()) if g.GetCellType(i) == 10)
u = g.GetPointData().GetArray("u").GetRange()
level = g.GetCellData().GetArray("level").GetRange()
vol = 0.0
for i in range(g.GetNumberOfCells()):
    p = g.GetCell(i).GetPoints()
    vol += abs(vtkTetra.ComputeVolume(p.GetPoint(0), p.GetPoint(1), p.GetPoint(2), p.GetPoint(3)))
print(g.GetNumberOfCells(), g.GetNumberOfPoints(), tets, repr(u[0]), repr(u[1]), int(level[1]), repr(vol))
