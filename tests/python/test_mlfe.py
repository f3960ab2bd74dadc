"""Tests of the Python package: NumPy and file volumes to validated glTF, extraction counts
against the command line's result, and bad input raising mlfe.Error instead of crashing.
Run by ctest with /usr/bin/python3 (tests/CMakeLists.txt): PYTHONPATH holds the built module,
MLFE_BINARY the command line and MLFE_SOURCE_DIR the repository."""
import json
import os
import re
import subprocess
import tempfile
import unittest

import numpy as np

import mlfe

SOURCE = os.environ["MLFE_SOURCE_DIR"]
BINARY = os.environ["MLFE_BINARY"]
SKULL = os.path.join(SOURCE, "samples", "ct_skull_64.nrrd")


def validate(path):
    """The Khronos glTF validator's verdict (tools/validate_gltf.js): (accepted, report)."""
    r = subprocess.run(["node", os.path.join(SOURCE, "tools", "validate_gltf.js"), path],
                       capture_output=True, text=True)
    return r.returncode == 0, r.stdout + r.stderr


def ply_counts(path):
    """(vertices, faces) from a PLY header."""
    with open(path, "rb") as f:
        header = f.read(4096).split(b"end_header")[0].decode("ascii")
    v = int(re.search(r"element vertex (\d+)", header).group(1))
    t = int(re.search(r"element face (\d+)", header).group(1))
    return v, t


def sphere(n=24, radius=8.0):
    """A distance-from-centre volume indexed [i, j, k], with its own shape along each axis."""
    i, j, k = np.meshgrid(np.arange(n), np.arange(n + 2), np.arange(n + 4), indexing="ij")
    c = [(n - 1) / 2, (n + 1) / 2, (n + 3) / 2]
    return np.sqrt((i - c[0]) ** 2 + (j - c[1]) ** 2 + (k - c[2]) ** 2).astype(np.float32), radius


class PythonModuleTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory(prefix="mlfe_python_test_")
        self.dir = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def test_array_to_glb(self):
        volume, radius = sphere()
        out = os.path.join(self.dir, "sphere.glb")
        summary = mlfe.convert(volume, out, iso=[radius], spacing=(0.5, 0.5, 0.5), origin=(10, 0, 0))
        self.assertGreater(summary["triangles"], 100)
        self.assertEqual(summary["bytes"], os.path.getsize(out))
        ok, report = validate(out)
        self.assertTrue(ok, report)
        # Placement follows spacing and origin: the sphere's vertices lie radius * 0.5 mm from
        # the centre (within the simplification and snapping tolerances).
        b = mlfe.build(volume, iso=[radius], spacing=(0.5, 0.5, 0.5), origin=(10, 0, 0))
        vertices = b.extract(iso=radius, simplify=0).vertices
        centre = np.array([10 + 0.5 * (volume.shape[0] - 1) / 2, 0.5 * (volume.shape[1] - 1) / 2,
                           0.5 * (volume.shape[2] - 1) / 2])
        distance = np.linalg.norm(vertices - centre, axis=1)
        self.assertLess(np.abs(distance - 0.5 * radius).max(), 0.5 * 0.5)

    def test_path_to_glb_with_hierarchy_and_report(self):
        out = os.path.join(self.dir, "skull.glb")
        h = os.path.join(self.dir, "skull.mlfeh")
        rep = os.path.join(self.dir, "skull.json")
        summary = mlfe.convert(SKULL, out, iso=[1.5, 3.0], hierarchy=h, report=rep)
        self.assertEqual(len(summary["surfaces"]), 2)
        ok, report = validate(out)
        self.assertTrue(ok, report)
        self.assertTrue(os.path.getsize(h) > 0 and os.path.getsize(rep) > 0)

    def test_same_bytes_as_the_command_line(self):
        """The module and `mlfe convert` run the same pipeline: same PLY bytes."""
        args = dict(iso=[2.5], max_vertices=3000, simplify=0)
        py_out = os.path.join(self.dir, "py.ply")
        cli_out = os.path.join(self.dir, "cli.ply")
        mlfe.convert(SKULL, py_out, **args)
        subprocess.run([BINARY, "convert", SKULL, "--iso", "2.5", "--max-vertices", "3000", "--simplify", "0",
                        "--quiet", "-o", cli_out], check=True, capture_output=True)
        with open(py_out, "rb") as a, open(cli_out, "rb") as b:
            self.assertEqual(a.read(), b.read())

    def test_extract_counts_match_the_cpp_result(self):
        for build_args, asset_args, cli in [
            (dict(max_vertices=3000), dict(simplify=0), ["--max-vertices", "3000", "--simplify", "0"]),
            ({}, {}, []),  # the defaults: surface-driven build, simplified and snapped
            (dict(rms="1%"), dict(snap=0, simplify=0.5, simplifier="bounded"),
             ["--rms", "1%", "--snap", "0", "--simplify", "0.5", "--simplifier", "bounded"]),
        ]:
            with self.subTest(cli=cli):
                b = mlfe.build(SKULL, iso=[2.5], **build_args)
                mesh = b.extract(iso=2.5, **asset_args)
                vertices, normals, indices = mesh.vertices, mesh.normals, mesh.triangles
                ply = os.path.join(self.dir, "cli.ply")
                subprocess.run([BINARY, "convert", SKULL, "--iso", "2.5", "--quiet", "-o", ply] + cli, check=True,
                               capture_output=True)
                self.assertEqual((len(vertices), len(indices)), ply_counts(ply))
                self.assertEqual(vertices.dtype, np.float32)
                self.assertEqual(indices.dtype, np.uint32)
                self.assertEqual(normals.shape, vertices.shape)
                self.assertLess(int(indices.max()), len(vertices))
                self.assertFalse(vertices.flags.owndata)  # a view of the C++ mesh

    def test_tet_mesh_input_matches_the_command_line(self):
        """A .vtu tetrahedral mesh as the input function: build and convert from Python give the
        command line's hierarchy and surfaces."""
        vtu = os.path.join(self.dir, "poisson.vtu")
        subprocess.run(["/usr/bin/python3", os.path.join(SOURCE, "bench", "data", "make_poisson_vtu.py"), vtu, "--n", "8"],
                       check=True, capture_output=True)
        b = mlfe.build(vtu, rms="1%")
        rep = os.path.join(self.dir, "cli.json")
        subprocess.run([BINARY, "build", vtu, "--rms", "1%", "--quiet", "-o", os.path.join(self.dir, "cli.mlfeh"),
                        "--report", rep], check=True, capture_output=True)
        with open(rep) as f:
            cli = json.load(f)
        self.assertGreater(b.vertex_count, 8)
        self.assertEqual((b.vertex_count, b.leaf_count, b.levels), (cli["vertices"], cli["elements"], cli["levels"]))
        py_ply, cli_ply = os.path.join(self.dir, "py.ply"), os.path.join(self.dir, "cli.ply")
        mlfe.convert(vtu, py_ply, iso=[0.3], rms="1%")
        subprocess.run([BINARY, "convert", vtu, "--iso", "0.3", "--rms", "1%", "--quiet", "-o", cli_ply], check=True,
                       capture_output=True)
        with open(py_ply, "rb") as f1, open(cli_ply, "rb") as f2:
            py_bytes, cli_bytes = f1.read(), f2.read()
        self.assertGreater(ply_counts(py_ply)[1], 0)
        self.assertEqual(py_bytes, cli_bytes)
        with self.assertRaisesRegex(mlfe.Error, "spacing: a file brings its own frame"):
            mlfe.build(vtu, spacing=(1, 1, 1))

    def test_build_reports_levels_counts_and_errors(self):
        b = mlfe.build(SKULL, rms="2%")
        self.assertEqual(b.dim, 3)
        self.assertGreater(b.levels, 1)
        self.assertEqual(b.values.shape, (b.vertex_count,))
        self.assertLessEqual(b.errors["rms_percent"], 2.0)
        self.assertEqual(b.report["vertices"], b.vertex_count)
        self.assertEqual(b.report["elements"], b.leaf_count)
        self.assertEqual(b.positions.shape, (b.vertex_count, 3))
        self.assertEqual(b.tetrahedra.shape, (b.leaf_count, 4))
        self.assertEqual(b.positions.dtype, np.float64)
        self.assertLess(int(b.tetrahedra.max()), b.vertex_count)
        self.assertRegex(repr(b), r"mlfe.Hierarchy\(dim=3, levels=\d+, vertices=\d+, tetrahedra=\d+")
        self.assertFalse(b.surface_driven)

    def test_read_volume_is_a_view_indexed_ijk(self):
        volume = mlfe.read_volume(SKULL)
        values = volume.values
        self.assertEqual(values.dtype, np.float32)
        self.assertEqual(values.ndim, 3)
        self.assertFalse(values.flags.owndata)
        self.assertEqual(len(volume.spacing), 3)
        self.assertEqual(volume.info["format"], "nrrd")
        self.assertEqual(volume.affine.shape, (4, 4))
        self.assertIn("mlfe.Volume(shape=(64, 64, 64)", repr(volume))
        # The Volume goes back in as it is, or the array with its affine: the file's asset.
        f = os.path.join(self.dir, "from_file.ply")
        mlfe.convert(SKULL, f, iso=[2.5])
        for name, call in [("volume", lambda out: mlfe.convert(volume, out, iso=2.5)),
                           ("affine", lambda out: mlfe.convert(values, out, iso=2.5, affine=volume.affine,
                                                               space=volume.space))]:
            with self.subTest(name):
                a = os.path.join(self.dir, name + ".ply")
                call(a)
                with open(a, "rb") as x, open(f, "rb") as y:
                    self.assertEqual(x.read(), y.read())

    def test_labels_match_the_command_line(self):
        """A label map with labels=True and a table: the command line's bytes, names, counts."""
        atlas = os.path.join(SOURCE, "tests", "data", "labels", "atlas_jhu_wm_labels_1mm.nii.gz")
        table = os.path.join(SOURCE, "tests", "data", "labels", "atlas_jhu_wm_labels_1mm.txt")
        out = os.path.join(self.dir, "py.glb")
        s = mlfe.convert(atlas, out, labels=[3, 4, 5], label_table=table)
        self.assertEqual(s["structure_count"], 3)
        self.assertEqual([x["name"] for x in s["structures"]],
                         ["Genu_of_corpus_callosum", "Body_of_corpus_callosum", "Splenium_of_corpus_callosum"])
        self.assertTrue(all(x["closed"] for x in s["structures"]))
        cli, rep = os.path.join(self.dir, "cli.glb"), os.path.join(self.dir, "cli.json")
        subprocess.run([BINARY, "convert", atlas, "--labels", "3-5", "--label-table", table, "-o", cli,
                        "--report", rep, "--quiet"], check=True)
        with open(rep) as f:
            self.assertEqual(json.load(f)["asset"]["structures"], s["structures"])
        ok, report = validate(out)
        self.assertTrue(ok, report)
        with self.assertRaises(mlfe.Error):
            mlfe.convert(np.full((4, 4, 4), 2.5, np.float32), os.path.join(self.dir, "bad.glb"), labels=True)
        self.assertFalse(os.path.exists(os.path.join(self.dir, "bad.glb")))
        # An option of other conversions, not of this one, is named as such (not "did you mean" itself).
        with self.assertRaisesRegex(mlfe.Error, "option 'bricks' does not apply"):
            mlfe.convert(atlas, os.path.join(self.dir, "b.glb"), labels=True, bricks=16)
        self.assertFalse(os.path.exists(os.path.join(self.dir, "b.glb")))

    def test_an_output_over_a_file_the_read_opens_is_refused(self):
        """A report over a raw volume's sidecar or over the label table (named or beside the
        volume) is refused before any work (pipeline::check_distinct_files, as every command
        checks), and the file is kept."""
        raw, table, beside = (os.path.join(self.dir, n) for n in ("v.raw", "t.txt", "v.txt"))
        with open(raw, "wb") as f:
            f.write(bytes([1] * 32 + [2] * 32))
        with open(raw + ".json", "w") as f:
            f.write('{"dims": [4, 4, 4], "dtype": "uint8"}')
        for t in (table, beside):
            with open(t, "w") as f:
                f.write("1 one\n2 two\n")
        out = os.path.join(self.dir, "o.glb")
        cases = [
            (lambda: mlfe.convert(raw, out, iso=[1.5], report=raw + ".json"), raw + ".json", r"\(volume .*v\.raw reads it\)"),
            (lambda: mlfe.convert(raw, out, labels=True, label_table=table, report=table), table, r"\(label_table\)"),
            (lambda: mlfe.convert(raw, out, labels=True, report=beside), beside, r"\(label_table\)"),
        ]
        for call, kept, reader in cases:
            with self.subTest(kept=kept):
                with open(kept, "rb") as f:
                    before = f.read()
                with self.assertRaisesRegex(mlfe.Error, "report: .* is also an input " + reader):
                    call()
                with open(kept, "rb") as f:
                    self.assertEqual(f.read(), before)
                self.assertFalse(os.path.exists(out))

    def test_bad_input_raises_with_the_message(self):
        out = os.path.join(self.dir, "bad.glb")
        cases = [
            (lambda: mlfe.convert(np.zeros((1, 5, 5), np.float32), out, iso=[0.5]), "at least 2 samples"),
            (lambda: mlfe.convert(os.path.join(self.dir, "missing.nrrd"), out, iso=[1]), "missing.nrrd"),
            (lambda: mlfe.convert(SKULL, out), "iso is required for 3D volumes"),
            (lambda: mlfe.convert(SKULL, out, iso=[1], norm="h2"), "norm"),
            (lambda: mlfe.convert(SKULL, out, iso=[1], simplfy=0.2), "unknown option 'simplfy'"),
            (lambda: mlfe.convert(SKULL, os.path.join(self.dir, "x.xyz"), iso=[1]), "unknown output type"),
            (lambda: mlfe.convert(np.full((4, 4, 4), np.nan, np.float32), out, iso=[1]), "NaN"),
            (lambda: mlfe.build(SKULL, max_level=99), "max_level: expected 0..40"),
            (lambda: mlfe.build(np.zeros((3, 3, 3, 3), np.float32)), "2D or 3D"),
            (lambda: mlfe.build(np.zeros((4, 4, 4), np.float32), spacing=(1, 0, 1)), "spacing"),
            (lambda: mlfe.build(np.zeros((4, 4, 4), np.float32), spacing=(1, 2)), "spacing: expected 3 numbers, got 2"),
            (lambda: mlfe.convert(SKULL, out, iso=float("nan")), "iso: expected finite numbers"),
            (lambda: mlfe.convert(SKULL, out, iso="80"), "iso: expected a number or a list"),
            (lambda: mlfe.convert(np.zeros((4, 4, 4)), out, iso=1, affine=np.eye(3)), "affine: expected a 4x4"),
            (lambda: mlfe.convert(SKULL, out, iso=1, spacing=(1, 1, 1)), "spacing: a file brings its own frame"),
        ]
        for call, message in cases:
            with self.subTest(message=message):
                with self.assertRaises(mlfe.Error) as caught:
                    call()
                self.assertIn(message, str(caught.exception))
                self.assertNotIn("--", str(caught.exception))  # keywords, not command-line flags
                self.assertIsInstance(caught.exception, ValueError)
                self.assertFalse(os.path.exists(out))


if __name__ == "__main__":
    unittest.main()
