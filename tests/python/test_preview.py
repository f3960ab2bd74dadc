"""The preview page (`mlfe convert --preview`, `mlfe.convert(preview=...)`) opened from disk in
headless Chromium (Debian's `chromium`, scripts/install_deps.sh): it loads, draws the asset,
lists every structure with its glTF node name, shows the report's figures and the --png image.
Run by ctest with /usr/bin/python3 (tests/CMakeLists.txt)."""
import json
import os
import struct
import subprocess
import sys
import tempfile
import unittest

import numpy as np

import mlfe

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import chromium_page  # noqa: E402  (beside this file)

SOURCE = os.environ["MLFE_SOURCE_DIR"]
BINARY = os.environ["MLFE_BINARY"]
SKULL = os.path.join(SOURCE, "samples", "ct_skull_64.nrrd")
ATLAS = os.path.join(SOURCE, "tests", "data", "labels", "atlas_jhu_wm_labels_1mm.nii.gz")
CHROMIUM = chromium_page.find_chromium()
NO_CHROMIUM = "chromium is not installed (Debian package `chromium`, scripts/install_deps.sh)"

# What the test reads from the page once its script says "ready" (or "failed").
QUERIES = {
    "status": 'document.getElementById("status").textContent',
    "structures": '[...document.querySelectorAll("#structures tr")].map(r => r.cells[2].textContent)',
    "figures": 'Object.fromEntries([...document.querySelectorAll("#figures tr")]'
               '.map(r => [r.cells[0].textContent.trim(), r.cells[1].textContent]))',
    "image": 'document.getElementById("image-box").hidden ? "" : document.getElementById("image").src.slice(0, 22)',
    "canvas_left": 'document.getElementById("view").getBoundingClientRect().left',
}
BACKGROUND = (0x1E, 0x1F, 0x22)  # the page's scene background


def node_names(glb):
    with open(glb, "rb") as f:
        data = f.read()
    (length,) = struct.unpack("<I", data[12:16])
    gltf = json.loads(data[20:20 + length])
    return [gltf["nodes"][n]["name"] for n in gltf["scenes"][0]["nodes"]]


def drawn_pixels(page, folder):
    """Pixels of the 3D view in the page's screenshot that differ from the background."""
    shot = os.path.join(folder, "shot.png")
    with open(shot, "wb") as f:
        f.write(page["png"])
    channels = mlfe.read_image(shot)["channels"]
    rgb = np.stack([channels[c] for c in ("R", "G", "B")], axis=-1)[:, int(page["canvas_left"]) + 2:]
    return int((np.abs(rgb * 255 - np.array(BACKGROUND)) > 8).any(axis=-1).sum())


@unittest.skipIf(CHROMIUM is None, NO_CHROMIUM)
class PreviewTest(unittest.TestCase):
    def open(self, page):
        return chromium_page.open_page(CHROMIUM, page, "document.body.dataset.state", QUERIES)

    def test_cli_preview_shows_the_draco_asset_figures_and_image(self):
        with tempfile.TemporaryDirectory() as d:
            glb, exr, png, page = (os.path.join(d, n) for n in ("skull.glb", "skull.exr", "skull.png", "skull.html"))
            r = subprocess.run([BINARY, "convert", SKULL, "--iso", "2", "-o", glb, "--render", exr, "--png", png,
                                "--preview", page, "--quiet"], capture_output=True, text=True)
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertEqual(r.stdout.split(), [glb, exr, png, page])
            shown = self.open(page)
            self.assertEqual(shown["ready"], "ready", shown)
            self.assertEqual(shown["console"], [])
            self.assertEqual(shown["structures"], node_names(glb))
            self.assertEqual(shown["structures"], ["iso 2"])
            # The triangles the page drew are the report's.
            self.assertEqual(shown["status"], "1 structures, %s triangles" % shown["figures"]["triangles"])
            self.assertIn("RMS error", shown["figures"])
            self.assertIn("build (s)", shown["figures"])
            self.assertEqual(shown["image"], "data:image/png;base64,")
            self.assertGreater(drawn_pixels(shown, d), 10000)

    def test_python_label_preview_lists_every_structure(self):
        with tempfile.TemporaryDirectory() as d:
            glb, page = os.path.join(d, "atlas.glb"), os.path.join(d, "atlas.html")
            mlfe.convert(ATLAS, glb, labels=True, preview=page)
            shown = self.open(page)
            self.assertEqual(shown["ready"], "ready", shown)
            names = node_names(glb)
            self.assertGreater(len(names), 40)
            self.assertEqual(shown["structures"], names)
            self.assertEqual(shown["image"], "")
            self.assertGreater(drawn_pixels(shown, d), 10000)

    def test_a_page_that_cannot_show_its_asset_says_so(self):
        with tempfile.TemporaryDirectory() as d:
            glb, page = os.path.join(d, "skull.glb"), os.path.join(d, "skull.html")
            mlfe.convert(SKULL, glb, iso=2, preview=page)
            with open(page) as f:
                text = f.read()
            start = text.index('id="mlfe-asset">') + len('id="mlfe-asset">')
            with open(page, "w") as f:
                f.write(text[:start] + "Z2xURg==" + text[text.index("</script>", start):])  # "glTF", cut
            shown = self.open(page)
            self.assertEqual(shown["ready"], "failed", shown)
            self.assertIn("could not show the asset", shown["status"])


class PreviewOptionsTest(unittest.TestCase):
    """Refusals before any work (no browser needed)."""

    def test_refusals_name_the_option_and_leave_nothing(self):
        with tempfile.TemporaryDirectory() as d:
            # Exit 2: bad input; 1: a usage error (an option without the one it needs).
            for args, message, status in (
                    (["-o", os.path.join(d, "a.ply"), "--preview", os.path.join(d, "a.html")], "not .glb or .gltf", 2),
                    (["-o", os.path.join(d, "a.glb"), "--preview", os.path.join(d, "a.txt")], "a.txt", 2),
                    (["-o", os.path.join(d, "a.glb"), "--png", os.path.join(d, "a.png")], "--render", 1)):
                r = subprocess.run([BINARY, "convert", SKULL, "--iso", "2", *args, "--quiet"], capture_output=True,
                                   text=True)
                self.assertEqual(r.returncode, status, r.stderr)
                self.assertIn(message, r.stderr)
                self.assertEqual(len(r.stderr.strip().splitlines()), 1, r.stderr)
            with self.assertRaisesRegex(mlfe.Error, "not .glb or .gltf"):
                mlfe.convert(SKULL, os.path.join(d, "a.stl"), iso=2, preview=os.path.join(d, "a.html"))
            self.assertEqual(os.listdir(d), [])


if __name__ == "__main__":
    unittest.main()
