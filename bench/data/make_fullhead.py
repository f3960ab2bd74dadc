#!/usr/bin/python3
"""make_fullhead.py: a full-head-like T1 MRI derived from the shared Colin27 brain.

Users convert whole heads (scalp, skull, noise), while the shared Colin27 MRI is brain-
extracted. This script puts a head around that brain, deterministically (fixed seed):

  1. brain mask: Colin27 > 0, closed and hole-filled;
  2. layers by the distance d (mm) outside the mask, with typical T1 intensities on
     Colin27's scale (grey ~85, white ~115): CSF 0-2 mm (25), inner skull table 2-4 (12),
     diploe 4-6 (70, marrow fat), outer table 6-8 (12), galea/muscle 8-10 (60),
     subcutaneous fat 10-13.5 (125: brighter than white matter, as in real T1 scans, so an
     iso-value between grey and white matter also cuts the scalp), skin 13.5-15 (75), air;
  3. partial volume: the layers are blurred with a 0.6 mm Gaussian and blended into the
     brain at its boundary;
  4. a smooth multiplicative bias field (+-6 %, the coil inhomogeneity of a real scan);
  5. Rician noise, sigma 3 (magnitude of a complex Gaussian), everywhere, also in the air.

--spacing 0.5 resamples the noiseless head trilinearly to 0.5 mm (362x434x362 = 56.9 M
voxels) before adding the noise, so the noise stays per voxel. The output is a gzipped
NIfTI-1 uint8 volume in Colin27's frame (origin and spacing scaled).

usage: bench/data/make_fullhead.py OUT.nii.gz [--spacing 1|0.5] [--brain PATH] [--sigma 3]
"""
import argparse
import gzip
import os
import struct

import numpy as np
from scipy import ndimage

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BRAIN = os.path.normpath(os.path.join(ROOT, "..", "shared", "data", "mri_colin27_brain.nii.gz"))

SEED = 20261123
LAYERS = [  # (outer distance mm, T1 value)
    (2.0, 25.0), (4.0, 12.0), (6.0, 70.0), (8.0, 12.0), (10.0, 60.0), (13.5, 125.0), (15.0, 75.0)]


def read_nifti(path):
    b = gzip.open(path).read()
    dims = struct.unpack("<8h", b[40:56])
    dtype = {2: np.uint8, 4: np.int16, 16: np.float32}[struct.unpack("<h", b[70:72])[0]]
    pix = struct.unpack("<8f", b[76:108])
    off = int(struct.unpack("<f", b[108:112])[0])
    n = dims[1] * dims[2] * dims[3]
    a = np.frombuffer(b[off:off + n * np.dtype(dtype).itemsize], dtype=dtype)
    return a.reshape(dims[3], dims[2], dims[1]).astype(np.float32), pix[1:4], b[:348]


def nifti_header(template, shape, spacing, origin=None):
    """uint8 NIfTI-1 header (348 bytes) from the template's: dims (shape is z, y, x), spacing,
    sform's rotation/scaling part scaled by the spacing ratio; its offset kept, or `origin`
    (x, y, z mm) when given."""
    h = bytearray(template)
    nz, ny, nx = shape
    h[40:56] = struct.pack("<8h", 3, nx, ny, nz, 1, 1, 1, 1)
    h[70:72] = struct.pack("<h", 2)  # uint8
    h[72:74] = struct.pack("<h", 8)
    old = struct.unpack("<8f", template[76:108])
    h[76:108] = struct.pack("<8f", old[0], spacing, spacing, spacing, *old[4:])
    h[108:112] = struct.pack("<f", 352.0)
    h[112:116] = struct.pack("<f", 1.0)  # scl_slope
    h[116:120] = struct.pack("<f", 0.0)
    # sform rows: scale the rotation/scaling part by the spacing ratio, keep the offset.
    ratio = spacing / old[1]
    for r, at in enumerate((280, 296, 312)):
        row = list(struct.unpack("<4f", template[at:at + 16]))
        offset = row[3] if origin is None else origin[r]
        h[at:at + 16] = struct.pack("<4f", row[0] * ratio, row[1] * ratio, row[2] * ratio, offset)
    return bytes(h)


def write_nifti(path, vol, spacing, template):
    """uint8 NIfTI-1, gzipped, with the template's header (nifti_header)."""
    h = nifti_header(template, vol.shape, spacing)
    data = np.clip(np.rint(vol), 0, 255).astype(np.uint8)
    with gzip.open(path, "wb", compresslevel=6) as f:
        f.write(bytes(h) + b"\0\0\0\0" + data.tobytes())


def head(brain):
    mask = ndimage.binary_closing(brain > 0, iterations=3)
    mask = ndimage.binary_fill_holes(mask)
    dist = ndimage.distance_transform_edt(~mask)
    layer = np.zeros_like(brain)
    inner = 0.0
    for outer, value in LAYERS:
        layer[(dist > inner) & (dist <= outer)] = value
        inner = outer
    layer = ndimage.gaussian_filter(layer, 0.6)
    # Inside the mask the brain's own values; across its boundary a short blend.
    w = np.clip(dist, 0.0, 1.0).astype(np.float32)
    out = (1 - w) * brain + w * layer
    out[~mask & (dist < 0.5)] = 0.5 * (brain[~mask & (dist < 0.5)] + layer[~mask & (dist < 0.5)])
    return out


def bias_field(shape, rng):
    coarse = rng.standard_normal((4, 4, 4)).astype(np.float32)
    zoom = [s / 4.0 for s in shape]
    f = ndimage.zoom(coarse, zoom, order=3)[: shape[0], : shape[1], : shape[2]]
    f = f / max(1e-6, np.abs(f).max())
    return 1.0 + 0.06 * f


def noiseless_head(brain_path, rng):
    """Steps 1-4 at the brain's 1 mm: (volume z, y, x float32, spacing, NIfTI header template).
    Draws the bias field from rng."""
    brain, spacing, template = read_nifti(brain_path)
    vol = head(brain)
    vol *= bias_field(vol.shape, rng)
    return vol, spacing, template


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--spacing", type=float, default=1.0, choices=[1.0, 0.5])
    ap.add_argument("--brain", default=BRAIN)
    ap.add_argument("--sigma", type=float, default=3.0)
    args = ap.parse_args()
    rng = np.random.default_rng(SEED)
    vol, spacing, template = noiseless_head(args.brain, rng)
    if args.spacing != spacing[0]:
        factor = spacing[0] / args.spacing
        vol = ndimage.zoom(vol, factor, order=1)
    n1 = rng.standard_normal(vol.shape, dtype=np.float32) * args.sigma
    n2 = rng.standard_normal(vol.shape, dtype=np.float32) * args.sigma
    vol = np.sqrt((vol + n1) ** 2 + n2 ** 2)
    write_nifti(args.out, vol, args.spacing, template)
    print(f"{args.out}: {vol.shape[2]}x{vol.shape[1]}x{vol.shape[0]} = {vol.size / 1e6:.1f} M voxels, "
          f"{args.spacing} mm")


if __name__ == "__main__":
    main()
