"""Tests of the package's frame and hierarchy API against the command line, and of mlfe.batch.
Run by ctest with /usr/bin/python3 (tests/CMakeLists.txt): PYTHONPATH holds the built package,
MLFE_BINARY the command line and MLFE_SOURCE_DIR the repository."""
import csv
import gzip
import json
import os
import struct
import subprocess
import tempfile
import unittest

import numpy as np

import mlfe

try:
    import nibabel
except ImportError:  # python3-nibabel (scripts/install_deps.sh)
    nibabel = None

SOURCE = os.environ["MLFE_SOURCE_DIR"]
BINARY = os.environ["MLFE_BINARY"]
SKULL = os.path.join(SOURCE, "samples", "ct_skull_64.nrrd")


def cli(*args):
    return subprocess.run([BINARY, *args], capture_output=True, text=True)


IGNORE_PROVENANCE = ["/asset/extras/tool", "/asset/extras/input", "/tool"]


def compare(expected, actual):
    """mlfe.compare's verdict (equal, text), ignoring the provenance that names the tool
    ("mlfe X (python)") and the input ("array" for arrays) in glTF extras and hierarchy metadata."""
    r = mlfe.compare(expected, actual, ignore=IGNORE_PROVENANCE)
    return r.equal, str(r)


def cli_compare(expected, actual):
    """`mlfe compare`'s exit status with the same ignores."""
    ignore = [a for p in IGNORE_PROVENANCE for a in ("--ignore", p)]
    return cli("compare", "--quiet", *ignore, expected, actual).returncode


def read_ply(path):
    """(vertices float32 (n, 3), triangles (m, 3)) of a binary little-endian PLY as the library
    writes it (x y z [nx ny nz] float, faces as uchar count + int indices)."""
    with open(path, "rb") as f:
        data = f.read()
    head, body = data.split(b"end_header\n", 1)
    lines = head.decode("ascii").splitlines()
    assert "format binary_little_endian 1.0" in lines, lines
    nv = nt = 0
    props = []
    for line in lines:
        w = line.split()
        if w[:2] == ["element", "vertex"]:
            nv = int(w[2])
        elif w[:2] == ["element", "face"]:
            nt = int(w[2])
        elif w[0] == "property" and w[1] == "float":
            props.append(w[2])
    vertex = np.frombuffer(body, dtype="<f4", count=nv * len(props)).reshape(nv, len(props))
    faces = np.frombuffer(body[nv * len(props) * 4:], dtype=np.dtype([("n", "u1"), ("i", "<i4", 3)]), count=nt)
    assert (faces["n"] == 3).all()
    return vertex[:, :3], faces["i"]


def blob(n=20, seed=0, shift=(0.0, 0.0, 0.0)):
    """A smooth anisotropic blob indexed [i, j, k] (shape n, n + 2, n - 2), values 0..~100."""
    i, j, k = np.meshgrid(np.arange(n), np.arange(n + 2), np.arange(n - 2), indexing="ij")
    c = np.array([n / 2 + shift[0], (n + 2) / 2 + shift[1], (n - 2) / 2 + shift[2]])
    r2 = ((i - c[0]) / 0.9) ** 2 + ((j - c[1]) / 1.2) ** 2 + (k - c[2]) ** 2
    rng = np.random.default_rng(seed)
    return (100 * np.exp(-r2 / (2 * (n / 5) ** 2)) + rng.normal(0, 0.5, r2.shape)).astype(np.float32)


def write_nrrd(path, values, spacing):
    """A raw little-endian float NRRD, x fastest."""
    header = ("NRRD0004\ntype: float\ndimension: 3\nsizes: %d %d %d\nspace: left-posterior-superior\n"
              "space directions: (%g,0,0) (0,%g,0) (0,0,%g)\nspace origin: (0,0,0)\nendian: little\n"
              "encoding: raw\n\n" % (*values.shape, *spacing))
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.asfortranarray(values, dtype="<f4").tobytes(order="F"))


class FrameTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory(prefix="mlfe_package_test_")
        self.dir = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def path(self, name):
        return os.path.join(self.dir, name)

    @unittest.skipIf(nibabel is None, "python3-nibabel is not installed (scripts/install_deps.sh)")
    def test_nibabel_affine_round_trip(self):
        """An oblique affine with permuted, flipped axes: nibabel's arrays and affine give the
        asset the command line makes from the NIfTI file (mlfe compare: equal), and the
        hierarchy's vertices land where the file's do."""
        values = blob()
        angle = np.radians(20)
        rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
        permute = np.array([[0, 0, -1], [1, 0, 0], [0, 1, 0]])  # i → y, j → z, k → -x
        affine = np.eye(4)
        affine[:3, :3] = rot @ permute @ np.diag([0.9, 1.1, 1.3])
        affine[:3, 3] = [-12.5, 30.0, 7.25]
        nii = self.path("scan.nii.gz")
        nibabel.save(nibabel.Nifti1Image(values, affine), nii)

        cli_glb = self.path("cli.glb")
        r = cli("convert", nii, "--iso", "40", "-o", cli_glb, "--quiet")
        self.assertEqual(r.returncode, 0, r.stderr)
        image = nibabel.load(nii)
        for name, call in [
            ("affine", lambda out: mlfe.convert(image.get_fdata(dtype=np.float32), out, iso=40, affine=image.affine)),
            ("volume", lambda out: mlfe.convert(mlfe.Volume.from_nibabel(image), out, iso=40)),
        ]:
            with self.subTest(name):
                out = self.path(name + ".glb")
                call(out)
                equal, report = compare(cli_glb, out)
                self.assertTrue(equal, report)
        # The same check fails when the direction is dropped (spacing and origin only).
        lossy = self.path("lossy.glb")
        mlfe.convert(values, lossy, iso=40, spacing=np.linalg.norm(affine[:3, :3], axis=0), origin=affine[:3, 3],
                     space="RAS")
        equal, report = compare(cli_glb, lossy)
        self.assertFalse(equal)
        self.assertIn("Hausdorff", report)
        # mlfe.compare is `mlfe compare`: the same verdicts.
        self.assertEqual((cli_compare(cli_glb, lossy), cli_compare(cli_glb, self.path("volume.glb"))), (1, 0))
        # The Volume's frame is the file's: read_volume of the NIfTI gives the same affine.
        v = mlfe.read_volume(nii)
        np.testing.assert_allclose(v.affine, affine, atol=1e-5)
        self.assertEqual(v.space, "RAS")

    def test_load_extract_equals_the_command_line_iso(self):
        """mlfe.load(x.mlfeh).extract(iso) is `mlfe iso x.mlfeh`'s surface: the same arrays, and
        Mesh.write gives the same PLY bytes."""
        h = self.path("skull.mlfeh")
        r = cli("build", SKULL, "--rms", "2%", "-o", h, "--quiet")
        self.assertEqual(r.returncode, 0, r.stderr)
        ply = self.path("cli.ply")
        r = cli("iso", h, "--iso", "2.5", "-o", ply, "--quiet")
        self.assertEqual(r.returncode, 0, r.stderr)
        hier = mlfe.load(h)
        mesh = hier.extract(iso=2.5)
        vertices, triangles = read_ply(ply)
        self.assertGreater(len(triangles), 100)
        np.testing.assert_array_equal(mesh.vertices, vertices)
        np.testing.assert_array_equal(mesh.triangles, triangles)
        out = self.path("py.ply")
        mesh.write(out)
        with open(out, "rb") as a, open(ply, "rb") as b:
            self.assertEqual(a.read(), b.read())
        self.assertEqual(repr(mesh), "mlfe.Mesh(vertices=%d, triangles=%d, iso=[2.5])" % (len(vertices),
                                                                                          len(triangles)))
        # The hierarchy's arrays: physical positions inside the volume's box, leaf tetrahedra
        # covering the box's volume, one value per vertex; Hierarchy(path) is load(path).
        self.assertEqual(hier.positions.shape, (hier.vertex_count, 3))
        self.assertEqual(hier.tetrahedra.shape, (hier.leaf_count, 4))
        self.assertEqual(hier.values.shape, (hier.vertex_count,))
        volume = mlfe.read_volume(SKULL)
        extent = (np.array(volume.shape) - 1) * np.array(volume.spacing)
        p = hier.positions[hier.tetrahedra]
        signed = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6
        self.assertAlmostEqual(np.abs(signed).sum() / np.prod(extent), 1.0, delta=0.35)
        self.assertEqual(mlfe.Hierarchy(h).vertex_count, hier.vertex_count)
        info = json.loads(cli("info", h, "--json").stdout)
        self.assertEqual(hier.levels, info.get("levels", hier.levels))
        with self.assertRaisesRegex(mlfe.Error, r"^iso: required for 3D hierarchies"):
            hier.extract()
        # Bad paths: the file named, nothing written.
        with self.assertRaisesRegex(mlfe.Error, "missing.mlfeh"):
            mlfe.load(self.path("missing.mlfeh"))
        with self.assertRaises(mlfe.Error):
            mesh.write(self.path("x.xyz"))
        self.assertFalse(os.path.exists(self.path("x.xyz")))

    def test_volume_checks_name_the_keyword(self):
        cases = [
            (lambda: mlfe.Volume(np.zeros((4, 4, 4)), spacing=(1, 2)), "spacing: expected 3 numbers, got 2"),
            (lambda: mlfe.Volume(np.zeros((4, 4, 4)), spacing=(1, -1, 1)), "spacing: expected finite positive"),
            (lambda: mlfe.Volume(np.zeros((4, 4, 4)), affine=np.zeros((4, 4))), "affine: the last row"),
            (lambda: mlfe.Volume(np.zeros((4, 4, 4)), affine=np.eye(4), spacing=(1, 1, 1)), "affine: give either"),
            (lambda: mlfe.Volume(np.zeros((4, 4, 4)), space="XYZ"), "space: expected 'RAS', 'LPS'"),
            (lambda: mlfe.Volume(np.zeros((4, 4, 4)), direction=np.zeros((3, 3))), "direction: the axes"),
            (lambda: mlfe.Volume(np.array([[[1.0, np.inf]]] * 2)), "values: 2 NaN or infinite values"),
            (lambda: mlfe.build(mlfe.Volume(np.zeros((4, 4, 4))), spacing=(1, 1, 1)), "spacing: the Volume brings"),
            (lambda: mlfe.build(np.zeros((4, 4, 4), np.float32), iso=[1, float("inf")]), "iso: expected finite"),
        ]
        for call, message in cases:
            with self.subTest(message=message):
                with self.assertRaises(mlfe.Error) as caught:
                    call()
                self.assertIn(message, str(caught.exception))
        # iso as a scalar, a list or an array: the same surface.
        b = mlfe.build(SKULL, iso=2.5, max_vertices=3000)
        counts = {len(b.extract(iso=v, simplify=0)) for v in (2.5, [2.5], np.array([2.5]))}
        self.assertEqual(len(counts), 1)


class PipelineCallsTest(unittest.TestCase):
    """render, info, export, progress and cancel against the command line."""

    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory(prefix="mlfe_calls_test_")
        self.dir = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def path(self, name):
        return os.path.join(self.dir, name)

    def hierarchy(self):
        h = self.path("skull.mlfeh")
        r = cli("build", SKULL, "--rms", "2%", "-o", h, "--quiet")
        self.assertEqual(r.returncode, 0, r.stderr)
        return h

    def test_render_arrays_equal_the_command_line_exr(self):
        h = self.hierarchy()
        exr = self.path("cli.exr")
        r = cli("render", h, "-o", exr, "--size", "64x48", "--azimuth", "30", "--elevation", "20", "--quiet")
        self.assertEqual(r.returncode, 0, r.stderr)
        image = mlfe.read_image(exr)
        result = mlfe.render(mlfe.load(h), size=(64, 48), azimuth=30, elevation=20)
        self.assertEqual(result.rgba.shape, (48, 64, 4))
        self.assertEqual(result.z.shape, (48, 64))
        self.assertEqual(result.written, [])
        self.assertGreater(float(result.rgba[..., 3].max()), 0.05)  # something is drawn
        for c, name in enumerate("RGBA"):  # the EXR stores half floats
            np.testing.assert_array_equal(result.rgba[..., c].astype(np.float16).astype(np.float32),
                                          image["channels"][name], err_msg=name)
        np.testing.assert_array_equal(result.z, image["channels"]["Z"])
        # Written from Python: the same image (mlfe.compare), and the path form takes "WxH".
        out = self.path("py.exr")
        written = mlfe.render(h, out, size="64x48", azimuth=30, elevation=20)
        self.assertEqual(written.written, [out])
        same = mlfe.compare(exr, out, ignore=["/mlfe/tool"])
        self.assertTrue(all(d[0].startswith("attribute") for d in same.differences), str(same))
        with self.assertRaisesRegex(mlfe.Error, "^size: "):
            mlfe.render(h, size="64by48")
        with self.assertRaisesRegex(mlfe.Error, "^camera: "):
            mlfe.render(h, camera="fisheye")

    def test_render_mesh_equals_the_command_line_exr(self):
        # A .vtu finite-element mesh is rendered as it is (no build), as `mlfe render mesh.vtu`.
        mesh = os.path.join(SOURCE, "tests", "data", "small_tets_raw.vtu")
        exr = self.path("mesh_cli.exr")
        r = cli("render", mesh, "-o", exr, "--size", "40x30", "--azimuth", "30", "--tf", "hot", "--quiet")
        self.assertEqual(r.returncode, 0, r.stderr)
        image = mlfe.read_image(exr)
        result = mlfe.render(mesh, size=(40, 30), azimuth=30, tf="hot")
        self.assertEqual(result.level, 0)
        self.assertGreater(float(result.rgba[..., 3].max()), 0.01)
        for c, name in enumerate("RGBA"):
            np.testing.assert_array_equal(result.rgba[..., c].astype(np.float16).astype(np.float32),
                                          image["channels"][name], err_msg=name)
        with self.assertRaisesRegex(mlfe.Error, "not a render option"):
            mlfe.render(mesh, rms=0.1)

    def test_cancel_from_progress_leaves_no_file(self):
        seen = []

        def stop_when_writing(fraction, stage):
            seen.append((fraction, stage))
            return stage != "writing"

        out, hier = self.path("skull.glb"), self.path("skull.mlfeh")
        with self.assertRaises(mlfe.Cancelled):
            mlfe.convert(SKULL, out, iso=2.5, hierarchy=hier, progress=stop_when_writing)
        self.assertFalse(os.path.exists(out) or os.path.exists(hier))
        self.assertEqual(os.listdir(self.dir), [])  # no temporary files either
        fractions = [f for f, _ in seen]
        self.assertEqual(fractions, sorted(fractions))
        self.assertTrue(all(0 <= f <= 1 for f in fractions))
        self.assertIn("building", {s for _, s in seen})
        # An exception in the callback cancels too and is raised as it is.
        def fail(fraction, stage):
            if stage == "building":
                raise KeyError("stop")
        with self.assertRaises(KeyError):
            mlfe.build(SKULL, rms="1%", progress=fail)
        # Without cancelling, the same call writes and reports 1 at the end.
        seen.clear()
        mlfe.convert(SKULL, out, iso=2.5, progress=lambda f, s: seen.append((f, s)))
        self.assertTrue(os.path.exists(out))
        self.assertEqual(seen[-1][0], 1.0)
        with self.assertRaisesRegex(mlfe.Error, "^progress: expected a callable"):
            mlfe.build(SKULL, progress=3)

    def test_info_export_and_the_option_vocabulary(self):
        h = self.hierarchy()
        def untimed(d):  # the reading time differs between runs
            return {k: untimed(v) if isinstance(v, dict) else v for k, v in d.items() if "seconds" not in k}

        self.assertEqual(untimed(mlfe.info(h)), untimed(json.loads(cli("info", h, "--json").stdout)))
        vol_info = mlfe.info(SKULL)
        self.assertEqual(untimed(vol_info), untimed(json.loads(cli("info", SKULL, "--json").stdout)))
        mine = mlfe.info(mlfe.read_volume(SKULL))
        self.assertEqual(mine["dims"], [64, 64, 64])
        # export: the leaf mesh, as `mlfe export`.
        py_vtu, cli_vtu = self.path("py.vtu"), self.path("cli.vtu")
        summary = mlfe.load(h).export(py_vtu)
        self.assertEqual(summary["written"], [py_vtu])
        self.assertEqual(cli("export", h, "-o", cli_vtu).returncode, 0)
        with open(py_vtu, "rb") as a, open(cli_vtu, "rb") as b:
            self.assertEqual(a.read(), b.read())
        # One vocabulary: the command line's spellings are accepted, bad ones named by keyword.
        b = mlfe.build(SKULL, rms="2%", max_memory="6G", norm="l2")
        self.assertGreater(b.vertex_count, 0)
        for kwargs, message in [(dict(max_memory="6X"), "max_memory"), (dict(rms="-1"), "rms"),
                                (dict(norm="h2"), "norm")]:
            with self.subTest(kwargs=kwargs):
                with self.assertRaises(mlfe.Error) as caught:
                    mlfe.build(SKULL, **kwargs)
                self.assertTrue(str(caught.exception).startswith(message), str(caught.exception))
                self.assertNotIn("--", str(caught.exception))

    def test_bad_compare_read_and_render_options_give_the_librarys_message(self):
        """Ranges are checked once, by the library: a bad option gives one message, naming the
        flag on the command line (exit 2 for compare, 1 otherwise) and the keyword in Python
        (mlfe.Error, a ValueError)."""
        h = self.hierarchy()
        raw = self.path("v.raw")
        with open(raw, "wb") as f:
            f.write(bytes(8 * 8 * 8))
        read = ["info", raw, "--raw-dims", "8", "8", "8"]
        cases = [  # the command line's arguments, its exit status, the same call in Python
            (["compare", SKULL, SKULL, "--tolerance", "-1"], 2, lambda: mlfe.compare(SKULL, SKULL, tolerance=-1)),
            (["compare", SKULL, SKULL, "--normal-angle", "-2"], 2,
             lambda: mlfe.compare(SKULL, SKULL, normal_angle=-2)),
            (["compare", SKULL, SKULL, "--psnr", "-3"], 2, lambda: mlfe.compare(SKULL, SKULL, psnr=-3)),
            (read + ["--raw-type", "int3"], 1, lambda: mlfe.read_volume(raw, raw_dims=(8, 8, 8), raw_type="int3")),
            (read + ["--raw-type", "u8", "--raw-endian", "middle"], 1,
             lambda: mlfe.read_volume(raw, raw_dims=(8, 8, 8), raw_type="u8", raw_endian="middle")),
            (read + ["--raw-type", "u8", "--raw-offset", "-4"], 1,
             lambda: mlfe.read_volume(raw, raw_dims=(8, 8, 8), raw_type="u8", raw_offset=-4)),
            (["render", h, "-o", self.path("x.exr"), "--frames", "0"], 1, lambda: mlfe.render(h, frames=0)),
        ]
        for args, status, call in cases:
            with self.subTest(args=args):
                r = cli(*args)
                self.assertEqual(r.returncode, status, r.stderr)
                message = r.stderr.strip()
                self.assertTrue(message.startswith("mlfe: --"), message)
                message = message[len("mlfe: "):]
                flag = message.split(":")[0]
                with self.assertRaises(ValueError) as caught:
                    call()
                self.assertEqual(str(caught.exception), message.replace(flag, flag[2:].replace("-", "_"), 1))
        self.assertEqual(mlfe.read_volume(raw, raw_dims=(8, 8, 8), raw_type="U8").shape, (8, 8, 8))


class StubTest(unittest.TestCase):
    def test_stubs_cover_the_public_api(self):
        """The shipped .pyi stubs declare every public name and member of the package, and the
        public callables have docstrings."""
        import ast
        import mlfe.batch
        import mlfe.distributed

        for module in (mlfe, mlfe.batch, mlfe.distributed):
            stub = os.path.splitext(module.__file__)[0] + ".pyi"
            with open(stub) as f:
                tree = ast.parse(f.read())
            declared = {}
            for node in tree.body:
                if isinstance(node, ast.ClassDef):
                    declared[node.name] = {n.name if hasattr(n, "name") else n.target.id for n in node.body
                                           if isinstance(n, (ast.FunctionDef, ast.AnnAssign))}
                elif isinstance(node, ast.FunctionDef):
                    declared[node.name] = set()
                elif isinstance(node, ast.AnnAssign):
                    declared[node.target.id] = set()
            for name in module.__all__:
                with self.subTest(module=module.__name__, name=name):
                    self.assertIn(name, declared)
                    obj = getattr(module, name)
                    if isinstance(obj, type):
                        members = {m for m in vars(obj) if not m.startswith("_")}
                        self.assertEqual(members - declared[name], set())
                    if callable(obj):
                        self.assertTrue(obj.__doc__, name)
        self.assertTrue(os.path.exists(os.path.join(os.path.dirname(mlfe.__file__), "py.typed")))


class BatchTest(unittest.TestCase):
    """mlfe.batch on a LocalCluster of 2 workers: five small scans (NIfTI and NRRD), one of them
    broken; the command line's outputs, the failure reported, resuming skips finished scans."""

    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory(prefix="mlfe_batch_test_")
        self.dir = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def make_study(self):
        study = os.path.join(self.dir, "study")
        os.makedirs(os.path.join(study, "site_b"))
        write_nrrd(os.path.join(study, "a.nrrd"), blob(16, seed=1), (1.0, 1.0, 1.2))
        write_nrrd(os.path.join(study, "site_b", "c.nrrd"), blob(18, seed=3, shift=(1, -1, 0)), (0.8, 0.8, 1.0))
        if nibabel is not None:
            for name, seed in (("b.nii.gz", 2), ("d.nii", 4)):
                affine = np.diag([1.0, 0.9, 1.1, 1.0])
                affine[:3, 3] = [5, -3, 2]
                nibabel.save(nibabel.Nifti1Image(blob(16, seed=seed), affine), os.path.join(study, name))
        else:
            write_nrrd(os.path.join(study, "b.nrrd"), blob(16, seed=2), (1.0, 0.9, 1.1))
            write_nrrd(os.path.join(study, "d.nrrd"), blob(16, seed=4), (1.0, 1.0, 1.0))
        with gzip.open(os.path.join(study, "broken.nii.gz"), "wb") as f:
            f.write(struct.pack("<i", 348) + b"\0" * 100)  # a truncated NIfTI header
        return study

    def test_find_scans_takes_whole_scans_in_any_case(self):
        """find_scans (VOLUME_SUFFIXES, from the library's table of formats) takes the files that
        are a scan by themselves, compound .nii.gz whole and in any case, and none of the rest."""
        import mlfe.batch

        scans = ["a.nii.gz", "B.NII", "c.Nrrd", "d.nhdr", "e.mha", "f.MHD", "g.vdb", "h.vtu", "i.msh",
                 "j.NII.GZ"]
        others = ["k.hdr", "k.img", "l.raw", "l.raw.json", "m.png", "n.pgm", "o.nrrd.gz", "p.bin", "q.dat",
                  "r.txt", "nii", "s.nii.gz.json"]
        for name in scans + others:
            open(os.path.join(self.dir, name), "wb").close()
        found = [os.path.basename(p) for p in mlfe.batch.find_scans(self.dir)]
        self.assertEqual(found, sorted(scans))
        self.assertEqual(mlfe.batch._stem(os.path.join(self.dir, "j.NII.GZ")), "j")

    def test_batch_on_a_local_cluster(self):
        import mlfe.batch

        study = self.make_study()
        out = os.path.join(self.dir, "assets")
        seen = []
        result = mlfe.batch.convert(study, out, iso=40, hierarchy=True, n_workers=2, on_row=seen.append,
                                    max_memory="20%")
        self.assertEqual(len(result.rows), 5)
        self.assertEqual(result.count("converted"), 4, result.rows)
        self.assertEqual(len(seen), 5)
        (bad, message), = result.failed
        self.assertTrue(bad.endswith("broken.nii.gz"))
        self.assertIn("broken.nii.gz", message)
        self.assertFalse(os.path.exists(os.path.join(out, "broken.glb")))
        # The command line's outputs, by the same names; sub-folders kept.
        asset = os.path.join(out, "site_b", "c.glb")
        for suffix in (".glb", ".mlfeh", ".json"):
            self.assertTrue(os.path.exists(os.path.join(out, "site_b", "c" + suffix)))
        expected = os.path.join(self.dir, "cli_c.glb")
        r = cli("convert", os.path.join(study, "site_b", "c.nrrd"), "--iso", "40", "--max-memory", "20%", "-o",
                expected, "--hierarchy", os.path.join(self.dir, "cli_c.mlfeh"), "--quiet")
        self.assertEqual(r.returncode, 0, r.stderr)
        equal, report = compare(expected, asset)
        self.assertTrue(equal, report)
        equal, report = compare(os.path.join(self.dir, "cli_c.mlfeh"), os.path.join(out, "site_b", "c.mlfeh"))
        self.assertTrue(equal, report)
        # The summary table, CSV and JSON, one row per scan in input order.
        with open(result.csv_path) as f:
            rows = list(csv.DictReader(f))
        self.assertEqual([r["status"] for r in rows].count("failed"), 1)
        for r in rows:
            if r["status"] == "converted":
                # The asset's figures, not the hierarchy's.
                self.assertGreater(int(r["asset_triangles"]), 0)
                self.assertGreater(int(r["asset_vertices"]), 0)
                self.assertNotEqual(r["asset_vertices"], r["hierarchy_vertices"])
        c_row = next(r for r in result.rows if r["input"].endswith("c.nrrd"))
        with open(os.path.join(out, "site_b", "c.json")) as f:
            c_report = json.load(f)
        self.assertEqual(c_row["asset_vertices"], sum(s["vertices"] for s in c_report["asset"]["surfaces"]))
        self.assertEqual(c_row["hierarchy_vertices"], c_report["vertices"])
        with open(result.json_path) as f:
            self.assertEqual(json.load(f)["converted"], 4)

        # Resuming: finished scans are skipped (files untouched), the broken one is retried, a
        # scan with a missing output is converted again.
        mtime = os.path.getmtime(asset)
        os.remove(os.path.join(out, "a.json"))
        again = mlfe.batch.convert(study, out, iso=40, hierarchy=True, n_workers=2, max_memory="20%")
        status = {os.path.basename(r["input"]): r["status"] for r in again.rows}
        self.assertEqual(status["a.nrrd"], "converted")
        self.assertEqual(status["c.nrrd"], "skipped")
        self.assertEqual(status["broken.nii.gz"], "failed")
        self.assertEqual(again.count("skipped"), 3)
        self.assertEqual(os.path.getmtime(asset), mtime)
        skipped = next(r for r in again.rows if r["input"].endswith("c.nrrd"))
        self.assertEqual(skipped["asset_triangles"], c_row["asset_triangles"])  # from the report written

    def test_a_changed_option_or_input_remakes_the_outputs(self):
        """Resuming skips a scan only when its record (options, iso, outputs, the input's size and
        time) matches: another option, another iso-value or a touched input converts it again."""
        import distributed
        import mlfe.batch

        study = os.path.join(self.dir, "study")
        os.makedirs(study)
        scan = os.path.join(study, "a.nrrd")
        write_nrrd(scan, blob(16, seed=1), (1.0, 1.0, 1.2))
        out = os.path.join(self.dir, "assets")
        asset = os.path.join(out, "a.glb")
        with distributed.Client(distributed.LocalCluster(n_workers=1, processes=False,
                                                         dashboard_address=None)) as client:
            def run(**options):
                r = mlfe.batch.convert(study, out, scheduler=client, **dict({"iso": 40}, **options))
                return r.rows[0]["status"]

            self.assertEqual(run(), "converted")
            first = open(asset, "rb").read()
            self.assertEqual(run(), "skipped")
            self.assertEqual(run(threads=1), "skipped")  # threads change no byte
            self.assertEqual(run(tolerance=0.5), "converted")
            self.assertNotEqual(open(asset, "rb").read(), first)
            self.assertEqual(run(tolerance=0.5), "skipped")
            self.assertEqual(run(), "converted")
            self.assertEqual(open(asset, "rb").read(), first)
            self.assertEqual(run(iso=45), "converted")
            self.assertEqual(run(iso=45), "skipped")
            stat = os.stat(scan)
            os.utime(scan, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))
            self.assertEqual(run(iso=45), "converted")
            os.remove(os.path.join(out, "a.mlfe-batch"))  # outputs of an older mlfe: no record
            self.assertEqual(run(iso=45), "converted")

    def test_a_misspelt_keyword_raises_before_any_task(self):
        """Options are checked once, before a cluster is asked for: a misspelt keyword or a value
        out of range raises at once with the library's message (no scheduler listens here)."""
        import mlfe.batch

        study = os.path.join(self.dir, "study")
        os.makedirs(study)
        write_nrrd(os.path.join(study, "a.nrrd"), blob(16, seed=1), (1.0, 1.0, 1.2))
        out = os.path.join(self.dir, "assets")
        nowhere = "tcp://127.0.0.1:9"
        with self.assertRaisesRegex(mlfe.Error, r"unknown option 'tolerence'; did you mean 'tolerance'\?"):
            mlfe.batch.convert(study, out, iso=40, tolerence=0.1, scheduler=nowhere)
        with self.assertRaisesRegex(mlfe.Error, "^max_level: "):
            mlfe.batch.convert(study, out, iso=40, max_level=99, scheduler=nowhere)
        with self.assertRaisesRegex(mlfe.Error, "^threads: "):
            mlfe.batch.convert(study, out, iso=40, threads=-2, scheduler=nowhere)
        with self.assertRaisesRegex(mlfe.Error, "labels and iso exclude each other"):
            mlfe.batch.convert(study, out, iso=40, labels=True, scheduler=nowhere)
        self.assertFalse(os.path.exists(out))  # nothing made, not even the folder


if __name__ == "__main__":
    unittest.main()
