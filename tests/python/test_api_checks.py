"""Issue #42's smaller surprises in the Python package: refusals with a clear message instead of
silent results, and "did you mean" for a misspelt keyword. Run by ctest with /usr/bin/python3
(tests/CMakeLists.txt)."""
import os
import tempfile
import unittest

import numpy as np

import mlfe


class ApiChecksTest(unittest.TestCase):
    def test_misspelt_keyword_names_the_nearest(self):
        with self.assertRaisesRegex(mlfe.Error, r"unknown option 'tolerence'; did you mean 'tolerance'\?"):
            mlfe.convert(np.zeros((8, 8, 8)), os.path.join(tempfile.gettempdir(), "never.glb"), iso=1, tolerence=1)
        with self.assertRaisesRegex(mlfe.Error, r"unknown option 'max_vertexes'; did you mean 'max_vertices'\?"):
            mlfe.build(np.zeros((8, 8, 8)), max_vertexes=100)
        with self.assertRaisesRegex(mlfe.Error, r"^unknown option 'zzzz'$"):
            mlfe.build(np.zeros((8, 8, 8)), zzzz=1)

    def test_iso_on_a_2d_array_is_refused(self):
        for call in (lambda v: mlfe.build(v, iso=1), lambda v: mlfe.convert(v, "never.glb", iso=1)):
            for values in (np.zeros((8, 8)), mlfe.Volume(np.zeros((8, 8)))):
                with self.assertRaisesRegex(mlfe.Error, "^iso: a 2D array is a height field"):
                    call(values)
        self.assertEqual(mlfe.build(np.random.default_rng(1).random((8, 8))).dim, 2)  # without iso: as before

    def test_png_without_out_is_refused(self):
        h = mlfe.build(np.random.default_rng(1).random((8, 8, 8)))
        with tempfile.TemporaryDirectory() as d:
            with self.assertRaisesRegex(mlfe.Error, "^png: .*give out="):
                mlfe.render(h, png=os.path.join(d, "x.png"))
            with self.assertRaisesRegex(mlfe.Error, "^png: .*give out="):
                h.render(png=os.path.join(d, "x.png"))
            self.assertEqual(os.listdir(d), [])
            r = mlfe.render(h, os.path.join(d, "x.exr"), png=os.path.join(d, "x.png"), size=(16, 16))
            self.assertEqual(sorted(os.listdir(d)), ["x.exr", "x.png"], r)


if __name__ == "__main__":
    unittest.main()
