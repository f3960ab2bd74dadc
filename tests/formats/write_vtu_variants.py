"""Rewrites a .vtu with VTK's own writer in every encoding the mlfe reader accepts, for
tests/formats/tet_mesh_reader_test.cpp: ascii, inline binary and appended (raw and base64),
each uncompressed and zlib-compressed, with UInt32 and UInt64 headers. Adds a 3-component point
array "vec" before the scalars and a Float32 copy "u32", so array selection is exercised.

    python3 write_vtu_variants.py IN.vtu OUT_DIR     (prints the files written)
"""
import os
import sys

import vtk


def main():
    src, out = sys.argv[1], sys.argv[2]
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(src)
    r.Update()
    grid = r.GetOutput()
    pd = grid.GetPointData()
    u = pd.GetArray("u")
    vec = vtk.vtkDoubleArray()
    vec.SetName("vec")
    vec.SetNumberOfComponents(3)
    u32 = vtk.vtkFloatArray()
    u32.SetName("u32")
    for i in range(grid.GetNumberOfPoints()):
        vec.InsertNextTuple3(i, 2 * i, 3 * i)
        u32.InsertNextValue(u.GetValue(i))
    arrays = [pd.GetArray(k) for k in range(pd.GetNumberOfArrays())]
    pd.Initialize()
    pd.AddArray(vec)
    for a in arrays:
        pd.AddArray(a)
    pd.AddArray(u32)
    for mode in ("ascii", "binary", "raw", "base64"):
        for compress in (False, True):
            for header in (32, 64):
                if mode == "ascii" and (compress or header == 64):
                    continue
                w = vtk.vtkXMLUnstructuredGridWriter()
                w.SetInputData(grid)
                name = os.path.join(out, f"{mode}_{'zlib' if compress else 'none'}_{header}.vtu")
                w.SetFileName(name)
                if mode == "ascii":
                    w.SetDataModeToAscii()
                elif mode == "binary":
                    w.SetDataModeToBinary()
                else:
                    w.SetDataModeToAppended()
                    w.SetEncodeAppendedData(mode == "base64")
                if compress:
                    w.SetCompressorTypeToZLib()
                    w.SetBlockSize(1024)  # several blocks per array
                else:
                    w.SetCompressorTypeToNone()
                if header == 64:
                    w.SetHeaderTypeToUInt64()
                else:
                    w.SetHeaderTypeToUInt32()
                if not w.Write():
                    sys.exit(f"cannot write {name}")
                print(name)


if __name__ == "__main__":
    main()
