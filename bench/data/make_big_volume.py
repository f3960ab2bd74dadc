#!/usr/bin/python3
"""make_big_volume.py: the scan-scale volumes of issue #39 (parallel, streaming, distributed
convert), derived from the full head of make_fullhead.py and written slab by slab.

The noiseless full head (make_fullhead.py steps 1-4: Colin27's brain with scalp, skull and
partial volume, times the bias field; 181 x 217 x 181 at 1 mm, 28 MB as float32) is the only
array held whole. Every output voxel samples it trilinearly (separable: z, then y, then x) at
spacing s mm, and gets its own Rician noise (sigma 3, as make_fullhead.py), so the fine grid
carries per-voxel noise and is not just a smoothed 1 mm scan. The volume is produced 8 z-planes
at a time into a 128-plane uint8 slab (the Zarr chunk depth), which is appended to each output;
peak memory is 0.75 GB for --size 2g (0.45 GB for 250m). The noise of z-plane k comes from a
generator seeded with (seed, k): the output does not depend on the slab sizes.

  --size 250m  640 x 768 x 640 = 315 M voxels, one head at s = 0.2817 mm (180 mm / 639: the
               head's x and z extents fill the grid; y is centred). Written as raw + JSON
               sidecar, uncompressed NIfTI-1 and OME-Zarr 0.4. Physical frame: Colin27's (RAS,
               the origin moved so that the head stays where the 1 mm scan has it).
  --size 2g    2048 x 1024 x 1024 = 2.15 G voxels: a mosaic of two heads side by side in x, each
               in a 1024^3 tile at s = 0.2111 mm (216 mm / 1023), the second mirrored (x -> -x),
               so the volume is twice as wide as a head, with air between; the noise is drawn
               for every voxel, so the two halves differ. Raw + sidecar and OME-Zarr 0.4 (no
               NIfTI: its int16 dims would hold it, but no reader of ours needs a 2 GB .nii).
               Frame: tile 0 in Colin27's frame as above, tile 1 beyond it in +x.

OME-Zarr: one level ("0"), axes z, y, x in millimetres, scale and translation giving the same
frame as the sidecar; Zarr v2 array, uint8, chunks 128^3, blosc zstd (clevel 1: about 0.77 of the bytes inside the
head, 0.4 in the air; lz4 does not compress the noise at all), "/" dimension
separator. Raw: uint8, x fastest; sidecar OUT.raw.json with dims, dtype, spacing, origin, space.

usage: bench/data/make_big_volume.py --size 250m|2g [--out DIR] [--brain PATH] [--sigma 3]
       writes DIR/head_250m.{raw,raw.json,nii,zarr} or DIR/heads_2g.{raw,raw.json,zarr}
       (default DIR /work/data/big, outside the repository).
"""
import argparse
import json
import os
import sys
import time

import numpy as np
import zarr
from numcodecs import Blosc

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import make_fullhead as fh  # noqa: E402

SIZES = {  # name: (file stem, output x, y, z, tiles along x, write NIfTI)
    "250m": ("head_250m", 640, 768, 640, 1, True),
    "2g": ("heads_2g", 2048, 1024, 1024, 2, False),
}
CHUNK = 128  # Zarr chunk edge; also the slab depth, so every chunk is written once
PLANES = 8  # z-planes computed together (float32 temporaries of PLANES x ny x tile)


def axis_samples(n_out, n_in, s):
    """Lower input index and weight of each output sample of a centred axis at spacing s."""
    x = (np.arange(n_out) - (n_out - 1) / 2.0) * s + (n_in - 1) / 2.0
    x = np.clip(x, 0.0, n_in - 1.0)  # outside the 1 mm grid: its border, which is air
    i0 = np.minimum(np.floor(x).astype(np.int64), n_in - 2)
    return i0, (x - i0).astype(np.float32)


def tile_planes(head, zs, ys, xs):
    """Trilinear samples of head (z, y, x) at the given planes: (len(z), ny, tile width)."""
    (z0, wz), (y0, wy), (x0, wx) = zs, ys, xs
    p = head[z0] * (1 - wz)[:, None, None] + head[z0 + 1] * wz[:, None, None]
    p = p[:, y0] * (1 - wy)[None, :, None] + p[:, y0 + 1] * wy[None, :, None]
    return p[:, :, x0] * (1 - wx) + p[:, :, x0 + 1] * wx


def rician(clean, k0, seed, sigma):
    """Rician noise per voxel; plane k's noise from its own generator (slab-size independent)."""
    out = np.empty(clean.shape, np.uint8)
    for i in range(clean.shape[0]):
        rng = np.random.default_rng([seed, k0 + i])
        n = rng.standard_normal((2,) + clean.shape[1:], dtype=np.float32)
        n *= sigma
        n[0] += clean[i]
        v = np.sqrt(n[0] * n[0] + n[1] * n[1])
        np.rint(v, out=v)
        np.clip(v, 0, 255, out=v)
        out[i] = v
    return out


def zarr_store(path, shape, spacing, origin):
    """An OME-Zarr 0.4 image with one level, its array "0" (z, y, x) to be filled."""
    root = zarr.group(store=zarr.DirectoryStore(path), overwrite=True)
    arr = root.create_dataset("0", shape=shape, chunks=(CHUNK,) * 3, dtype=np.uint8, fill_value=0,
                              compressor=Blosc(cname="zstd", clevel=1, shuffle=Blosc.NOSHUFFLE),
                              dimension_separator="/")
    root.attrs["multiscales"] = [{
        "version": "0.4",
        "name": os.path.basename(path),
        "axes": [{"name": a, "type": "space", "unit": "millimeter"} for a in "zyx"],
        "datasets": [{"path": "0", "coordinateTransformations": [
            {"type": "scale", "scale": [spacing] * 3},
            {"type": "translation", "translation": [origin[2], origin[1], origin[0]]}]}],
    }]
    return arr


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", required=True, choices=sorted(SIZES))
    ap.add_argument("--out", default="/work/data/big")
    ap.add_argument("--brain", default=fh.BRAIN)
    ap.add_argument("--sigma", type=float, default=3.0)
    args = ap.parse_args()
    stem, nx, ny, nz, tiles, nifti = SIZES[args.size]
    tile = nx // tiles
    head, spacing_in, template = fh.noiseless_head(args.brain, np.random.default_rng(fh.SEED))
    hz, hy, hx = head.shape
    # The finest spacing at which the head fits the tile in every axis (y, the longest, decides).
    s = max((hx - 1) / (tile - 1), (hy - 1) / (ny - 1), (hz - 1) / (nz - 1))
    spacing = s * spacing_in[0]
    ys, xs = axis_samples(ny, hy, s), axis_samples(tile, hx, s)
    z0, wz = axis_samples(nz, hz, s)
    # Output voxel 0 sits at input index (n_in - 1) / 2 - (n_out - 1) / 2 * s in the 1 mm frame.
    sform_origin = [float(np.frombuffer(template[at + 12:at + 16], "<f4")[0]) for at in (280, 296, 312)]
    origin = [o + ((n_in - 1) / 2.0 - (n_out - 1) / 2.0 * s) * spacing_in[0]
              for o, n_in, n_out in zip(sform_origin, (hx, hy, hz), (tile, ny, nz))]
    os.makedirs(args.out, exist_ok=True)
    base = os.path.join(args.out, stem)
    with open(base + ".raw.json", "w") as f:
        json.dump({"dims": [nx, ny, nz], "dtype": "uint8", "endian": "little", "spacing": [spacing] * 3,
                   "origin": origin, "space": "RAS"}, f)
    arr = zarr_store(base + ".zarr", (nz, ny, nx), spacing, origin)
    outs = [open(base + ".raw", "wb")]
    if nifti:
        outs.append(open(base + ".nii", "wb"))
        outs[-1].write(fh.nifti_header(template, (nz, ny, nx), spacing, origin) + b"\0\0\0\0")
    t0 = time.time()
    slab = np.empty((CHUNK, ny, nx), np.uint8)
    for k0 in range(0, nz, CHUNK):
        depth = min(CHUNK, nz - k0)
        for p in range(0, depth, PLANES):
            ks = slice(k0 + p, k0 + min(depth, p + PLANES))
            clean = tile_planes(head, (z0[ks], wz[ks]), ys, xs)
            if tiles == 2:
                clean = np.concatenate([clean, clean[:, :, ::-1]], axis=2)
            slab[p:p + clean.shape[0]] = rician(clean, ks.start, fh.SEED, args.sigma)
        for f in outs:
            f.write(slab[:depth].tobytes())
        arr[k0:k0 + depth] = slab[:depth]
        print(f"  z {k0 + depth}/{nz} ({time.time() - t0:.0f} s)", flush=True)
    for f in outs:
        f.close()
    print(f"{base}: {nx}x{ny}x{nz} = {nx * ny * nz / 1e6:.1f} M voxels uint8, spacing {spacing:.4f} mm, "
          f"{tiles} head(s); {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
