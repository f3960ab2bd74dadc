"""OME-Zarr input (formats/zarr_reader.h): stores written with zarr-python (python3-zarr) give the
asset of the same volume read from NIfTI, whatever their compressor, chunking, axes and units;
bad stores give one line and exit 2, and no output. Run by ctest with /usr/bin/python3
(tests/CMakeLists.txt): MLFE_BINARY is the command line."""
import json
import os
import shutil
import subprocess
import tempfile
import unittest

import nibabel as nib
import numcodecs
import numpy as np
import zarr

BINARY = os.environ["MLFE_BINARY"]


def volume():
    """A smooth blob whose iso-surface crosses many chunks: 30 x 26 x 21 (x, y, z), uint16."""
    x, y, z = np.meshgrid(np.arange(30), np.arange(26), np.arange(21), indexing="ij")
    r = np.sqrt(((x - 14.2) / 11) ** 2 + ((y - 12.7) / 9) ** 2 + ((z - 10.1) / 7) ** 2)
    return (1000 * np.exp(-r * r) + 7 * np.sin(x * 0.9 + y * 0.4)).astype(np.uint16)  # indexed [x, y, z]


def multiscales(axes, scale, translation, levels=1):
    ds = [{"path": str(k), "coordinateTransformations": [
        {"type": "scale", "scale": [s * 2 ** k if a["type"] == "space" else s for s, a in zip(scale, axes)]},
        {"type": "translation", "translation": translation}]} for k in range(levels)]
    return [{"version": "0.4", "axes": axes, "datasets": ds}]


SPACE = [{"name": "z", "type": "space", "unit": "millimeter"}, {"name": "y", "type": "space", "unit": "millimeter"},
         {"name": "x", "type": "space", "unit": "millimeter"}]


def write_store(path, data_xyz, compressor, chunks=(8, 7, 9), separator=".", axes=SPACE,
                scale=(3.0, 1.25, 0.75), translation=(10.0, -5.0, 2.5), fill_value=0, levels=1, lead=()):
    """An OME-Zarr image of data_xyz (stored z, y, x after any leading size-1 axes)."""
    root = zarr.open_group(path, mode="w")
    zyx = np.ascontiguousarray(data_xyz.transpose(2, 1, 0)).reshape(lead + data_xyz.shape[::-1])
    for k in range(levels):
        level = zyx[..., ::2 ** k, ::2 ** k, ::2 ** k]
        root.create_dataset(str(k), data=level, chunks=(1,) * len(lead) + chunks, compressor=compressor,
                            dimension_separator=separator, fill_value=fill_value)
    root.attrs["multiscales"] = multiscales(axes, list(scale), list(translation), levels)


def nifti(path, data_xyz, spacing_xyz, origin_xyz):
    affine = np.diag(list(spacing_xyz) + [1.0])
    affine[:3, 3] = origin_xyz
    nib.save(nib.Nifti1Image(data_xyz, affine), path)


def edit(path, old, new):
    with open(path) as f:
        text = f.read()
    assert old in text, (path, old)
    with open(path, "w") as f:
        f.write(text.replace(old, new))


def mlfe(*args):
    return subprocess.run([BINARY, *args], capture_output=True, text=True)


class ZarrTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.dir = self.tmp.name
        self.data = volume()

    def tearDown(self):
        self.tmp.cleanup()

    def convert(self, src, name):
        out = os.path.join(self.dir, name)
        r = mlfe("convert", src, "--iso", "500", "-o", out)
        self.assertEqual(r.returncode, 0, r.stderr)
        with open(out, "rb") as f:
            return f.read()

    def reference(self, spacing_xyz=(0.75, 1.25, 3.0), origin_xyz=(2.5, -5.0, 10.0)):
        path = os.path.join(self.dir, "ref.nii.gz")
        nifti(path, self.data, spacing_xyz, origin_xyz)
        return self.convert(path, "ref.ply")

    def test_each_compressor_gives_the_nifti_asset(self):
        ref = self.reference()
        compressors = {
            "none": None,
            "blosc_lz4": numcodecs.Blosc(cname="lz4", clevel=5, shuffle=numcodecs.Blosc.SHUFFLE),
            "blosc_zstd": numcodecs.Blosc(cname="zstd", clevel=3, shuffle=numcodecs.Blosc.BITSHUFFLE),
            "zlib": numcodecs.Zlib(level=6),
            "gzip": numcodecs.GZip(level=5),
            "zstd": numcodecs.Zstd(level=3),
        }
        for name, comp in compressors.items():
            with self.subTest(compressor=name):
                store = os.path.join(self.dir, name + ".zarr")
                write_store(store, self.data, comp, separator="/" if name == "zlib" else ".")
                self.assertEqual(self.convert(store, name + ".ply"), ref)

    def test_bricks_read_the_store_box_by_box_with_the_nifti_surface(self):
        # The store is read window by window (no whole volume, no hierarchy); the NIfTI, read
        # whole because a hierarchy is written too, gives the same bricked surface.
        ref_nii = os.path.join(self.dir, "ref.nii.gz")
        nifti(ref_nii, self.data, (0.75, 1.25, 3.0), (2.5, -5.0, 10.0))
        whole = os.path.join(self.dir, "whole.ply")
        r = mlfe("convert", ref_nii, "--iso", "500", "--bricks", "8", "-o", whole, "--hierarchy",
                 os.path.join(self.dir, "whole.mlfeh"))
        self.assertEqual(r.returncode, 0, r.stderr)
        store = os.path.join(self.dir, "bricks.zarr")
        write_store(store, self.data, numcodecs.Blosc(cname="zstd"))
        out, report = os.path.join(self.dir, "bricks.ply"), os.path.join(self.dir, "bricks.json")
        r = mlfe("convert", store, "--iso", "500", "--bricks", "8", "-o", out, "--report", report)
        self.assertEqual(r.returncode, 0, r.stderr)
        with open(report) as f:
            self.assertTrue(json.load(f)["read_in_windows"])
        with open(out, "rb") as a, open(whole, "rb") as b:
            self.assertEqual(a.read(), b.read())
        # Python's bricks= reads the store the same way.
        import mlfe as package
        py = os.path.join(self.dir, "bricks_py.ply")
        package.convert(store, py, iso=500, bricks=8)
        with open(py, "rb") as a, open(whole, "rb") as b:
            self.assertEqual(a.read(), b.read())

    def test_units_levels_and_leading_axes(self):
        # Micrometres: the frame is converted to millimetres.
        store = os.path.join(self.dir, "um.zarr")
        um = [dict(a, unit="micrometer") for a in SPACE]
        write_store(store, self.data, numcodecs.Zstd(), axes=um, scale=(3000.0, 1250.0, 750.0),
                    translation=(10000.0, -5000.0, 2500.0))
        self.assertEqual(self.convert(store, "um.ply"), self.reference())
        # t, c, z, y, x with one time point and one channel.
        store = os.path.join(self.dir, "tczyx.zarr")
        axes = [{"name": "t", "type": "time"}, {"name": "c", "type": "channel"}] + SPACE
        write_store(store, self.data, numcodecs.Blosc(), axes=axes, scale=(1.0, 1.0, 3.0, 1.25, 0.75),
                    translation=(0.0, 0.0, 10.0, -5.0, 2.5), lead=(1, 1))
        self.assertEqual(self.convert(store, "tczyx.ply"), self.reference())
        # Level 1 of a two-level pyramid: every second voxel at twice the spacing.
        store = os.path.join(self.dir, "levels.zarr")
        write_store(store, self.data, numcodecs.Blosc(), levels=2)
        out = os.path.join(self.dir, "l1.ply")
        r = mlfe("convert", store, "--zarr-level", "1", "--iso", "500", "-o", out)
        self.assertEqual(r.returncode, 0, r.stderr)
        path = os.path.join(self.dir, "l1.nii.gz")
        nifti(path, np.ascontiguousarray(self.data[::2, ::2, ::2]), (1.5, 2.5, 6.0), (2.5, -5.0, 10.0))
        with open(out, "rb") as f:
            self.assertEqual(f.read(), self.convert(path, "l1_ref.ply"))
        r = mlfe("info", store, "--zarr-level", "2")
        self.assertEqual(r.returncode, 2)
        self.assertIn("has levels 0..1", r.stderr)

    def assert_refused(self, store, needle):
        out = os.path.join(self.dir, "bad.glb")
        r = mlfe("convert", store, "--iso", "500", "-o", out)
        self.assertEqual(r.returncode, 2, r.stderr)
        lines = r.stderr.strip().splitlines()
        self.assertEqual(len(lines), 1, r.stderr)
        self.assertIn(needle, lines[0])
        self.assertFalse(os.path.exists(out))

    def test_bad_stores_exit_2_with_one_line(self):
        base = os.path.join(self.dir, "bad.zarr")

        def fresh(**kw):
            shutil.rmtree(base, ignore_errors=True)
            write_store(base, self.data, numcodecs.Zlib(), **kw)
            return base

        # A missing chunk where the array has no fill value.
        fresh(fill_value=None)
        os.remove(os.path.join(base, "0", "1.1.1"))
        self.assert_refused(base, "missing chunk")
        # A dtype mlfe does not read.
        fresh()
        meta = os.path.join(base, "0", ".zarray")
        edit(meta, '"<u2"', '"<c8"')
        self.assert_refused(base, "dtype")
        # An unknown compressor.
        fresh()
        edit(meta, '"zlib"', '"lzma"')
        self.assert_refused(base, "compressor")
        # A lying shape: chunks claimed larger than the ones stored.
        fresh()
        edit(meta, "[\n        8,", "[\n        9,")
        self.assert_refused(base, "chunk")
        # A corrupt chunk.
        fresh()
        with open(os.path.join(base, "0", "0.0.0"), "r+b") as f:
            f.seek(2)
            f.write(b"\xff\xff\xff\xff")
        self.assert_refused(base, "0.0.0")
        # Three channels: one scalar field is read.
        rgb = os.path.join(self.dir, "rgb.zarr")
        root = zarr.open_group(rgb, mode="w")
        root.create_dataset("0", data=np.zeros((3, 4, 5, 6), np.uint8), chunks=(1, 4, 5, 6))
        root.attrs["multiscales"] = [{"version": "0.4", "axes": [{"name": "c", "type": "channel"}] + SPACE,
                                      "datasets": [{"path": "0", "coordinateTransformations": [
                                          {"type": "scale", "scale": [1, 1, 1, 1]}]}]}]
        self.assert_refused(rgb, "one scalar field")


if __name__ == "__main__":
    unittest.main()
