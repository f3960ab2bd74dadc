"""Meshes in and out of Python (issue 42): mlfe.read_mesh reads every asset format back within
its encoding's quantization, Mesh from arrays writes every format, and compare judges geometry,
not provenance, between any mix of files and Mesh objects. Run by ctest with /usr/bin/python3
(tests/CMakeLists.txt): PYTHONPATH holds the built package, MLFE_BINARY the command line and
MLFE_SOURCE_DIR the repository."""
import os
import subprocess
import tempfile
import unittest

import numpy as np

import mlfe

SOURCE = os.environ["MLFE_SOURCE_DIR"]
BINARY = os.environ["MLFE_BINARY"]
SKULL = os.path.join(SOURCE, "samples", "ct_skull_64.nrrd")
FORMATS = (".glb", ".gltf", ".drc", ".ply", ".obj", ".stl", ".off")
# glTF's frame, as gltf_writer.h states it: metres = M @ millimetres ('' is taken as RAS).
TO_GLTF = {"RAS": np.array([[-1e-3, 0, 0], [0, 0, 1e-3], [0, 1e-3, 0]]),
           "LPS": np.array([[1e-3, 0, 0], [0, 0, 1e-3], [0, -1e-3, 0]])}


def cli(*args):
    return subprocess.run([BINARY, *args], capture_output=True, text=True)


def chebyshev_gap(a, b):
    """The largest distance, per coordinate, from a point of `a` to its nearest point of `b`."""
    return max(np.abs(b[None, :, :] - chunk[:, None, :]).max(axis=2).min(axis=1).max()
               for chunk in np.array_split(a.astype(float), max(1, len(a) // 256)))


def sphere(n=12, radius=20.0, centre=(5.0, -3.0, 40.0)):
    """A UV sphere in millimetres: positions, triangles (counter-clockwise from outside), normals."""
    theta, phi = np.meshgrid(np.linspace(0, np.pi, n + 1)[1:-1], np.linspace(0, 2 * np.pi, 2 * n, endpoint=False),
                             indexing="ij")
    unit = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1).reshape(-1, 3)
    unit = np.vstack([[0, 0, 1], unit, [0, 0, -1]])
    ring = 2 * n
    tris = [(0, 1 + j, 1 + (j + 1) % ring) for j in range(ring)]
    for i in range(n - 2):
        for j in range(ring):
            a, b = 1 + i * ring + j, 1 + i * ring + (j + 1) % ring
            tris += [(a, a + ring, b), (b, a + ring, b + ring)]
    last = len(unit) - 1
    tris += [(last, 1 + (n - 2) * ring + (j + 1) % ring, 1 + (n - 2) * ring + j) for j in range(ring)]
    return (unit * radius + centre).astype(np.float32), np.array(tris, dtype=np.int64), unit.astype(np.float32)


class MeshTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory(prefix="mlfe_mesh_test_")
        self.dir = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def path(self, name):
        return os.path.join(self.dir, name)

    def test_read_back_every_format_within_draco_quantization(self):
        """One conversion written in every format, with and without Draco, reads back as the
        .ply's millimetres: exactly (float formats) or within half of Draco's grid step, read from
        the file, per coordinate."""
        h = mlfe.build(SKULL, iso=2.5, max_vertices=3000)
        reference = h.extract(2.5)
        ref = reference.positions
        tolerance = min(h.frame[0]) / 10  # write's default: a tenth of the smallest voxel spacing, mm
        cases = [(".glb", True), (".gltf", True)] + [(ext, ext == ".drc") for ext in FORMATS]
        for ext, draco in cases:
            with self.subTest(ext=ext, draco=draco):
                out = self.path("skull%s%s" % ("_draco" if draco else "", ext))
                reference.write(out, draco=draco)
                m = mlfe.read_mesh(out)
                gltf = ext in (".glb", ".gltf")
                self.assertEqual((m.frame, m.units), ("gltf", "m") if gltf else ("scan", "mm"))
                self.assertEqual(m.format, ext[1:])
                self.assertEqual(len(m.triangles), len(reference.triangles))
                self.assertEqual(m.triangles.dtype, np.uint32)
                self.assertTrue(m.triangles.max() < len(m.positions))
                if gltf:
                    self.assertEqual(m.names, ["iso 2.5"])
                    self.assertEqual(m.iso, [2.5])
                    self.assertEqual(m.space, reference.space)
                    self.assertEqual(m.extras["iso_values"], [2.5])
                    # glTF's frame is the writer's map of the millimetres; to_scan_frame undoes it.
                    mm = m.to_scan_frame()
                    self.assertEqual(mm.frame, "scan")
                    in_gltf = ref @ TO_GLTF[reference.space or "RAS"].T
                    self.assertLess(chebyshev_gap(m.positions, in_gltf), 1e-3 * tolerance * 1.001 if draco else 1e-7)
                else:
                    mm = m
                step = m.quantization_steps[0] * (1000.0 if gltf else 1.0)
                self.assertEqual(step > 0, draco)
                bound = step / 2 * 1.001 if draco else 1e-4
                self.assertLess(chebyshev_gap(mm.positions, ref), bound)
                self.assertLess(chebyshev_gap(ref, mm.positions), bound)
                if draco:
                    self.assertLessEqual(step, 2 * tolerance * 1.001)
                self.assertTrue(mlfe.compare(reference, m).equal)

    def test_mesh_from_arrays_writes_and_reads_every_format(self):
        """Mesh(positions, triangles, normals, name, label, color) written in every format and read
        back: names, labels and colours per glTF node, and a glTF of several nodes by name."""
        positions, triangles, normals = sphere()
        skull = mlfe.Mesh(positions, triangles, normals, name="skull", label=3, color=(0.9, 0.8, 0.7))
        self.assertEqual((skull.name, skull.label, skull.color, skull.frame), ("skull", 3, (0.9, 0.8, 0.7, 1.0), "scan"))
        np.testing.assert_array_equal(skull.positions, positions)
        np.testing.assert_array_equal(skull.triangles, triangles)
        self.assertFalse(skull.positions.flags.writeable)
        p2, t2, _ = sphere(8, 6.0, (-20.0, 10.0, 0.0))
        brain = mlfe.Mesh(p2, t2.astype(np.int32), name="brain", label=7, color=(0.2, 0.4, 0.9, 0.5))
        both = mlfe.Mesh.join([skull, brain])
        self.assertEqual((both.names, both.labels, both.surface_triangles), (["skull", "brain"], [3, 7],
                                                                           [len(triangles), len(t2)]))
        self.assertIsNone(both.name)
        for ext in FORMATS:
            for draco in (True, False) if ext in (".glb", ".gltf") else (ext == ".drc",):
                with self.subTest(ext=ext, draco=draco):
                    out = self.path("both%s%s" % ("_draco" if draco else "", ext))
                    both.write(out, draco=draco, tolerance=0.05)
                    read = mlfe.read_mesh(out)
                    bound = 0.05 * 1.001 if draco else 1e-4
                    back = read.to_scan_frame()
                    self.assertLess(chebyshev_gap(back.positions, both.positions), bound)
                    self.assertLess(chebyshev_gap(both.positions, back.positions), bound)
                    if ext not in (".glb", ".gltf"):
                        self.assertEqual(read.names, [""])
                        continue
                    meshes = mlfe.read_meshes(out)
                    self.assertEqual(list(meshes), ["skull", "brain"])
                    self.assertEqual([meshes["skull"].label, meshes["brain"].label], [3, 7])
                    self.assertEqual(meshes["brain"].color, (0.2, 0.4, 0.9, 0.5))
                    self.assertEqual(len(meshes["brain"].triangles), len(t2))
                    # Written again from glTF's frame: the same asset.
                    again = self.path("again" + ext)
                    read.write(again, draco=draco)
                    self.assertTrue(mlfe.compare(out, again).equal, str(mlfe.compare(out, again)))

    def test_compare_judges_geometry_not_provenance(self):
        """The golden cases of issue 42: an array's conversion equals the file's; a Draco .glb
        equals its --no-draco twin within the file's quantization step, and says so; files and
        Mesh objects mix; --strict/strict=True compares provenance and encoding; millimetre-scaled
        and mirrored copies still differ."""
        volume = mlfe.read_volume(SKULL)
        from_array, from_file, plain = self.path("array.glb"), self.path("file.glb"), self.path("plain.glb")
        mlfe.convert(volume, from_array, iso=2.5, max_vertices=3000)
        self.assertEqual(cli("convert", SKULL, "--iso", "2.5", "--max-vertices", "3000", "--quiet", "-o",
                             from_file).returncode, 0)
        self.assertEqual(cli("convert", SKULL, "--iso", "2.5", "--max-vertices", "3000", "--no-draco", "--quiet",
                             "-o", plain).returncode, 0)
        same = mlfe.compare(from_file, from_array)
        self.assertTrue(same.equal, str(same))
        self.assertIn("/asset/extras/input", same.notes[0])
        strict = mlfe.compare(from_file, from_array, strict=True)
        self.assertIn("structure /asset/extras/input", str(strict))
        self.assertEqual((cli("compare", from_file, from_array).returncode,
                          cli("compare", "--strict", from_file, from_array).returncode), (0, 1))

        twin = mlfe.compare(from_file, plain)
        self.assertTrue(twin.equal, str(twin))
        self.assertIn("the Draco quantization step of EXPECTED", " ".join(twin.notes))
        self.assertIn("encoding /mlfe/encoding", str(mlfe.compare(from_file, plain, strict=True)))
        run = cli("compare", from_file, plain)
        self.assertEqual(run.returncode, 0, run.stdout)
        self.assertIn("widened to", run.stdout)

        # Files and meshes mix: a .glb against the Mesh read from it and its millimetres.
        m = mlfe.read_mesh(from_file)
        for expected, actual in ((from_file, m), (m, plain), (m.to_scan_frame(), from_file), (plain, m.to_scan_frame())):
            with self.subTest(expected=type(expected).__name__, actual=type(actual).__name__):
                r = mlfe.compare(expected, actual)
                self.assertTrue(r.equal, str(r))

        mm = m.to_scan_frame()
        scaled = mlfe.Mesh(mm.positions * 1000, mm.triangles, mm.normals)
        r = mlfe.compare(from_file, scaled)
        self.assertFalse(r.equal)
        self.assertIn("millimetres instead of metres?", str(r))
        mirrored_positions = mm.positions.copy()
        mirrored_positions[:, 0] = 2 * mirrored_positions[:, 0].mean() - mirrored_positions[:, 0]
        r = mlfe.compare(mm, mlfe.Mesh(mirrored_positions, mm.triangles))
        self.assertFalse(r.equal)
        self.assertIn("handedness", str(r))

    def test_bad_meshes_name_the_keyword_or_file(self):
        positions, triangles, _ = sphere(4)
        cases = [
            (lambda: mlfe.Mesh(positions[:, :2], triangles), "positions: expected an (n, 3) array"),
            (lambda: mlfe.Mesh(positions, triangles + 1), "triangles: vertex index %d outside" % len(positions)),
            (lambda: mlfe.Mesh(positions, triangles.astype(float)), "triangles: expected an (m, 3) array of integer"),
            (lambda: mlfe.Mesh(positions, triangles, positions[:3]), "normals: 3 rows for %d positions" % len(positions)),
            (lambda: mlfe.Mesh(positions, triangles, color=(2, 0, 0)), "color: expected numbers in [0, 1]"),
            (lambda: mlfe.Mesh(positions, triangles, label="skull"), "label: expected an integer"),
            (lambda: mlfe.Mesh(np.full((3, 3), np.nan), [[0, 1, 2]]), "positions: NaN or infinite"),
            (lambda: mlfe.Mesh.join([]), "meshes: expected at least one Mesh"),
            (lambda: mlfe.compare(positions, SKULL), "expected: expected a file path or a Mesh"),
        ]
        for call, message in cases:
            with self.subTest(message=message):
                with self.assertRaises(mlfe.Error) as e:
                    call()
                self.assertIn(message, str(e.exception))
        notes = self.path("notes.txt")
        with open(notes, "w") as f:
            f.write("not a mesh")
        with self.assertRaises(mlfe.Error) as e:
            mlfe.read_mesh(notes)
        self.assertEqual(str(e.exception), notes + ": not a mesh file (expected .glb, .gltf, .drc, .ply, .obj, .stl "
                                                   "or .off)")
        glb = self.path("m.glb")
        mlfe.Mesh(positions, triangles).write(glb)
        with self.assertRaises(mlfe.Error):
            mlfe.Mesh.join([mlfe.read_mesh(glb), mlfe.Mesh(positions, triangles)])


if __name__ == "__main__":
    unittest.main()
