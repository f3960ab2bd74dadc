"""Issue #42, items 2 and 5: a hierarchy file keeps its build record (a loaded hierarchy tells
what its build did, with the keys a build gives), threads= changes no byte, and the leaf
tetrahedra are positively oriented. Run by ctest with /usr/bin/python3 (tests/CMakeLists.txt)."""
import json
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np

import mlfe

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from test_package import blob, write_nrrd  # noqa: E402

BINARY = os.environ.get("MLFE_BINARY", "mlfe")
SOURCE = os.environ.get("MLFE_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))


def without_times(value):
    """A report or record with every time and machine figure taken out (files keep none)."""
    if isinstance(value, dict):
        return {k: without_times(v) for k, v in value.items()
                if not k.endswith("seconds") and k not in ("peak_rss_mb", "input")}
    if isinstance(value, list):
        return [without_times(v) for v in value]
    return value


class BuildRecordTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory(prefix="mlfe_record_test_")
        self.dir = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def test_a_loaded_hierarchy_tells_what_its_build_did(self):
        """Saved and loaded, a build gives back its record, stop reason, errors (same keys and
        values), noise and report, for a global target and for surface-driven refinement."""
        for kwargs in ({"max_vertices": 3000}, {"iso": 40}):
            with self.subTest(**kwargs):
                built = mlfe.build(blob(20), **kwargs)
                path = os.path.join(self.dir, "h.mlfeh")
                built.save(path)
                loaded = mlfe.load(path)
                record = built.build_record
                self.assertTrue(record["stop_reason"])
                self.assertTrue(record["per_iteration"] or record["surface_passes"])
                self.assertEqual(loaded.build_record, record)
                self.assertEqual(mlfe.info(path)["metadata"]["build"], record)
                for name in ("stop_reason", "surface_driven", "memory_limited", "errors"):
                    self.assertEqual(getattr(loaded, name), getattr(built, name), name)
                self.assertEqual(sorted(loaded.errors), ["l2", "psnr_db", "rms", "rms_percent"])
                self.assertEqual(loaded.surface_driven, "iso" in kwargs)
                # Every key of the report but the times (a file keeps none: same input and
                # options, same bytes), the input's name and the volume's (loaded: no volume).
                volume_keys = {"dims", "voxels", "spacing"}
                self.assertEqual(without_times(loaded.report),
                                 {k: v for k, v in without_times(built.report).items() if k not in volume_keys})
                self.assertIsNone(loaded.seconds)
                self.assertGreater(built.seconds, 0)
                options = record["options"]
                self.assertEqual(options["iso"], [40.0] if "iso" in kwargs else [])
                self.assertEqual(options["max_vertices"], kwargs.get("max_vertices", 0))

    def test_the_command_lines_file_keeps_its_report_and_old_files_read_as_before(self):
        """`mlfe build`'s file gives back its --report's record; a file without a record reads as
        before (header error figures, no stop reason)."""
        volume = os.path.join(self.dir, "v.nrrd")
        write_nrrd(volume, blob(18, seed=2), (1.0, 0.9, 1.1))
        out, report = os.path.join(self.dir, "v.mlfeh"), os.path.join(self.dir, "v.json")
        r = subprocess.run([BINARY, "build", volume, "-o", out, "--report", report, "--quiet"], capture_output=True,
                           text=True)
        self.assertEqual(r.returncode, 0, r.stderr)
        with open(report) as f:
            cli_report = json.load(f)
        loaded = mlfe.load(out)
        for key in ("stop_reason", "per_iteration", "surface_passes", "memory_limited", "noise_sigma",
                    "rms_target", "iterations", "rms_error", "psnr_db"):
            self.assertEqual(without_times(loaded.report[key]), without_times(cli_report[key]), key)
        self.assertGreater(cli_report["noise_sigma"], 0)
        info = subprocess.run([BINARY, "info", out, "--json"], capture_output=True, text=True)
        self.assertEqual(info.returncode, 0, info.stderr)
        self.assertEqual(json.loads(info.stdout)["metadata"]["build"], loaded.build_record)

        old = mlfe.load(os.path.join(SOURCE, "tests", "data", "small_lattice_v3.mlfeh"))
        self.assertNotIn("build", old.metadata)
        self.assertEqual(old.stop_reason, "")
        self.assertEqual(old.build_record["per_iteration"], [])
        self.assertEqual(sorted(old.errors), ["max", "norm", "psnr_db", "rms", "sample_error_bound"])


class ThreadsAndOrientationTest(unittest.TestCase):
    def test_threads_give_the_same_bytes(self):
        """threads= on the calls that work: the same files whatever the count; a bad count is
        refused with the keyword's name."""
        volume = blob(24, seed=5)
        with tempfile.TemporaryDirectory() as d:
            files = {}
            for n in (1, 2, 0):
                out, h = os.path.join(d, "a%d.glb" % n), os.path.join(d, "a%d.mlfeh" % n)
                mlfe.convert(volume, out, iso=40, hierarchy=h, threads=n)
                built = mlfe.build(volume, iso=40, threads=n)
                e = os.path.join(d, "e%d.ply" % n)
                built.write(e, iso=40, threads=n)
                files[n] = [open(p, "rb").read() for p in (out, h, e)]
            self.assertEqual(files[1], files[2])
            self.assertEqual(files[1], files[0])
            for bad in (-1, 1.5, "2", True):
                with self.assertRaisesRegex(mlfe.Error, "^threads: "):
                    mlfe.build(volume, threads=bad)

    def test_tetrahedra_are_positively_oriented(self):
        """Every leaf tetrahedron has positive volume in the physical frame, a mirrored one too."""
        mirrored = np.diag([-1.0, 0.9, 1.1, 1.0])
        for affine in (np.eye(4), mirrored):
            h = mlfe.build(mlfe.Volume(blob(20), affine=affine), max_vertices=4000)
            p, t = h.positions, h.tetrahedra
            a = p[t[:, 0]]
            volume6 = np.einsum("ij,ij->i", p[t[:, 1]] - a, np.cross(p[t[:, 2]] - a, p[t[:, 3]] - a))
            self.assertGreater(len(t), 1000)
            self.assertTrue((volume6 > 0).all(), int((volume6 <= 0).sum()))
            np.testing.assert_array_equal(np.sort(t, axis=1), np.sort(h.cells, axis=1))


if __name__ == "__main__":
    unittest.main()
