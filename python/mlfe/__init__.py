"""mlfe: adaptive multilevel finite-element approximation of volume data.

Volumes (NIfTI, NRRD, MetaImage, raw, OpenVDB, NumPy arrays) become adaptive tetrahedral
hierarchies (Grosso, Lürig & Ertl, IEEE Vis 1997), iso-surface assets (glTF + Draco, PLY, OBJ,
STL, OFF) and ray-cast images, with the same pipeline and options as the ``mlfe`` command line.

Arrays and frames
-----------------
A volume is a NumPy array indexed ``[i, j, k]`` (x, y, z; a 2D height field ``[i, j]``) together
with its frame: the map from voxel indices to physical millimetres. Keep the frame with the
values: a :class:`Volume` carries both, :func:`read_volume` returns one, and every call accepts
it as it is. Passing only ``spacing``/``origin`` drops the direction (an oblique or flipped scan
then lands in the wrong place).

- nibabel: ``mlfe.Volume(img.get_fdata(dtype=np.float32), affine=img.affine)`` (or
  :meth:`Volume.from_nibabel`). nibabel's affine maps voxel ``(i, j, k)`` to **RAS+**
  millimetres, which is how the command line reads a NIfTI file's sform/qform, so the result is
  the command line's on the same file; ``space`` defaults to ``"RAS"`` with ``affine=``.
- SimpleITK: ``sitk.GetArrayFromImage`` returns the array indexed ``[k, j, i]`` (z first).
  Transpose it and pass ITK's frame, which is **LPS**:
  ``mlfe.Volume(arr.transpose(2, 1, 0), spacing=img.GetSpacing(), origin=img.GetOrigin(),
  direction=np.reshape(img.GetDirection(), (3, 3)), space="LPS")``.

Errors, progress and cancel
---------------------------
Bad input raises :class:`mlfe.Error` (a ``ValueError``) with a one-line message naming the
keyword or file at fault; no output file is left behind. Every long call takes
``progress=callback``: ``callback(fraction, stage)`` is called on the calling thread with the
fraction done in [0, 1] and the stage ("reading", "building", "extracting", "simplifying",
"rendering", "resampling", "writing"); returning ``False`` cancels the call, which then raises
:class:`mlfe.Cancelled` (an ``mlfe.Error``) and leaves no output file. An exception raised in
the callback, or Ctrl-C, cancels the same way and is raised as it is.

Threads
-------
Every call that does work takes ``threads=n``: at most n of the library's worker threads while
it runs (0 or None: every core), as the command line's ``--threads``. The results and files are
the same, byte for byte, whatever the count.
"""
from __future__ import annotations

import functools
import math
import numbers
import os

import numpy as np

from . import _mlfe
from ._mlfe import Cancelled, Error

__version__ = _mlfe.__version__
Error.__doc__ = "Bad input or options: a one-line message naming the keyword or file (a ValueError)."
Cancelled.__doc__ = "A call stopped by its progress callback (or Ctrl-C); it left no output file."

__all__ = [
    "Cancelled",
    "CompareResult",
    "Error",
    "Hierarchy",
    "Mesh",
    "Volume",
    "RenderResult",
    "build",
    "compare",
    "convert",
    "export",
    "info",
    "load",
    "read_image",
    "read_mesh",
    "read_meshes",
    "read_volume",
    "render",
    "__version__",
]

_SPACES = ("", "RAS", "LPS")


# ---------------------------------------------------------------------------------------------
def _thread_limit(threads):
    """The checked limit of ``threads=`` (a context manager)."""
    if isinstance(threads, bool) or not isinstance(threads, numbers.Integral):
        raise Error("threads: expected a whole number of threads (0: every core), got %r" % (threads,))
    return _mlfe.thread_limit(int(threads))


def _threaded(function):
    """Adds ``threads=``: at most that many of the library's worker threads while the call runs
    (0 or None: every core), as the command line's ``--threads``; the output is the same, byte
    for byte, whatever the count."""

    @functools.wraps(function)
    def call(*args, threads=None, **kwargs):
        if threads is None:
            return function(*args, **kwargs)
        with _thread_limit(threads):
            return function(*args, **kwargs)

    call.__doc__ = (function.__doc__ or "") + "\n\n    ``threads``: see the module documentation.\n"
    return call


# ---------------------------------------------------------------------------------------------
# Argument checks, each naming the keyword.
def _fspath(value):
    return os.fspath(value) if isinstance(value, (str, os.PathLike)) else None


def _numbers(name, value, lengths, positive=False):
    """A tuple of finite floats whose length is one of `lengths`."""
    try:
        v = [float(x) for x in np.asarray(value, dtype=float).reshape(-1)]
    except (TypeError, ValueError):
        raise Error("%s: expected numbers, got %r" % (name, value)) from None
    if isinstance(value, (str, bytes)) or len(v) not in lengths:
        want = " or ".join(str(n) for n in lengths)
        raise Error("%s: expected %s numbers, got %d" % (name, want, len(v)))
    for x in v:
        if not math.isfinite(x) or (positive and x <= 0):
            raise Error("%s: expected finite%s numbers, got %s" % (name, " positive" if positive else "", v))
    return tuple(v)


def _matrix(name, value):
    try:
        m = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise Error("%s: expected a 3x3 matrix, got %r" % (name, value)) from None
    if m.shape != (3, 3):
        raise Error("%s: expected a 3x3 matrix, got shape %s" % (name, m.shape))
    if not np.isfinite(m).all():
        raise Error("%s: non-finite entries" % name)
    if abs(np.linalg.det(m)) < 1e-12:
        raise Error("%s: the axes are degenerate (determinant 0)" % name)
    return m


def _space(value):
    space = "" if value is None else str(value)
    if space not in _SPACES:
        raise Error("space: expected 'RAS', 'LPS' or '' (unknown), got %r" % value)
    return space


def _iso_values(iso):
    """iso=1.5, iso=[1.5, 3], iso=np.array(...): a list of finite floats, or None."""
    if iso is None:
        return None
    if isinstance(iso, (str, bytes, bool)):
        raise Error("iso: expected a number or a list of numbers, got %r" % (iso,))
    if isinstance(iso, numbers.Real):
        values = [float(iso)]
    else:
        try:
            values = [float(x) for x in np.asarray(iso, dtype=float).reshape(-1)]
        except (TypeError, ValueError):
            raise Error("iso: expected a number or a list of numbers, got %r" % (iso,)) from None
    if not values:
        raise Error("iso: expected at least one value")
    for v in values:
        if not math.isfinite(v):
            raise Error("iso: expected finite numbers, got %s" % values)
    return values


def _affine_frame(affine):
    """spacing, origin and direction (rows) of a voxel → millimetre affine (4x4 or 3x4)."""
    try:
        a = np.array(affine, dtype=float)
    except (TypeError, ValueError):
        raise Error("affine: expected a 4x4 matrix, got %r" % (affine,)) from None
    if a.shape not in ((4, 4), (3, 4)):
        raise Error("affine: expected a 4x4 (or 3x4) matrix, got shape %s" % (a.shape,))
    if not np.isfinite(a).all():
        raise Error("affine: non-finite entries")
    if a.shape == (4, 4) and not np.allclose(a[3], [0, 0, 0, 1]):
        raise Error("affine: the last row must be 0 0 0 1, got %s" % a[3].tolist())
    columns = a[:3, :3]
    spacing = np.linalg.norm(columns, axis=0)
    for axis, s in enumerate(spacing):
        if not s > 0:
            raise Error("affine: voxel axis %d has a zero step" % axis)
    direction = columns / spacing
    if abs(np.linalg.det(direction)) < 1e-12:
        raise Error("affine: the voxel axes are degenerate (determinant 0)")
    return tuple(float(s) for s in spacing), tuple(float(o) for o in a[:3, 3]), direction


# ---------------------------------------------------------------------------------------------
class Volume:
    """Sampled values with their frame: voxel ``(i, j, k)`` lies at
    ``origin + direction @ (spacing * (i, j, k))`` millimetres, in the anatomical ``space``.

    ``Volume(values, affine=A)`` takes a 4x4 voxel → millimetre affine (nibabel's ``img.affine``,
    RAS+, so ``space`` defaults to ``"RAS"``); ``Volume(values, spacing=..., origin=...,
    direction=..., space=...)`` takes ITK's/NRRD's parts (``direction`` rows: column ``a`` is
    voxel axis ``a``'s unit step). ``values`` is indexed ``[i, j, k]`` (or ``[i, j]`` for a
    height field); a SimpleITK array ``[k, j, i]`` must be transposed first (see the module
    documentation). Values are kept as given (no copy); the library copies them once, as
    float32, when a call reads them.
    """

    __slots__ = ("values", "spacing", "origin", "direction", "space", "info")

    def __init__(self, values, *, affine=None, spacing=None, origin=None, direction=None, space=None, info=None):
        self.values = _checked_values("values", values)
        n = self.values.ndim
        if affine is not None:
            if spacing is not None or origin is not None or direction is not None:
                raise Error("affine: give either affine or spacing/origin/direction, not both")
            spacing, origin, direction = _affine_frame(affine)
            space = "RAS" if space is None else space
            spacing = spacing[:n]
        self.spacing = _numbers("spacing", (1.0,) * n if spacing is None else spacing, (n,), positive=True)
        self.origin = _numbers("origin", (0.0,) * n if origin is None else origin, (n, 3))
        self.direction = np.eye(3) if direction is None else _matrix("direction", direction)
        self.space = _space(space)
        self.info = {} if info is None else dict(info)

    @classmethod
    def from_nibabel(cls, image):
        """A nibabel image (NIfTI-1/2): its scaled data as float32 and ``image.affine`` (RAS+).
        nibabel's affine is the sform when its code is set, else the qform, as the command line
        reads the file; without either, nibabel's fallback affine is used."""
        data = np.asarray(image.get_fdata(dtype=np.float32))
        if data.ndim == 4 and data.shape[3] == 1:
            data = data[..., 0]
        return cls(data, affine=image.affine, space="RAS")

    @property
    def shape(self):
        return self.values.shape

    @property
    def ndim(self):
        return self.values.ndim

    @property
    def affine(self):
        """The 4x4 voxel ``(i, j, k)`` → millimetre matrix (in ``space``)."""
        a = np.eye(4)
        s = np.ones(3)
        s[: len(self.spacing)] = self.spacing
        a[:3, :3] = self.direction * s
        a[: len(self.origin), 3] = self.origin
        return a

    def _core_args(self):
        return dict(
            spacing=list(self.spacing),
            origin=list(self.origin),
            direction=self.direction.tolist(),
            space=self.space,
        )

    def __repr__(self):
        return "mlfe.Volume(shape=%s, dtype=%s, spacing=%s, origin=%s, space=%r%s)" % (
            tuple(self.values.shape),
            self.values.dtype,
            tuple(round(s, 6) for s in self.spacing),
            tuple(round(o, 6) for o in self.origin),
            self.space,
            "" if np.allclose(self.direction, np.eye(3)) else ", oblique",
        )


def _checked_values(name, values):
    a = np.asarray(values)
    if a.dtype == object or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)
                                 or a.dtype == bool):
        raise Error("%s: expected a numeric array, got dtype %s" % (name, a.dtype))
    if a.ndim not in (2, 3):
        raise Error("%s: expected a 2D or 3D array, got %d dimensions" % (name, a.ndim))
    if np.issubdtype(a.dtype, np.floating):
        bad = ~np.isfinite(a)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            raise Error("%s: %d NaN or infinite values (the first at %s); replace them first" %
                        (name, int(bad.sum()), first))
    return a


def _volume_args(volume, spacing, origin, direction, affine, space):
    """The extension's (volume, frame keywords) for a path, a Volume or an array + frame."""
    path = _fspath(volume)
    frame_given = [k for k, v in (("spacing", spacing), ("origin", origin), ("direction", direction),
                                  ("affine", affine), ("space", space)) if v is not None]
    if path is not None:
        if frame_given:
            raise Error("%s: a file brings its own frame (read it with mlfe.read_volume to change it)" %
                        frame_given[0])
        return path, {}
    if isinstance(volume, Volume):
        if frame_given:
            raise Error("%s: the Volume brings its own frame (make a new Volume to change it)" % frame_given[0])
        v = volume
    else:
        v = Volume(_checked_values("volume", volume), affine=affine, spacing=spacing, origin=origin,
                   direction=direction, space=space)
    return v.values, v._core_args()


# ---------------------------------------------------------------------------------------------
class Mesh:
    """Triangle surfaces: extracted (:meth:`Hierarchy.extract`), read from an asset file
    (:func:`read_mesh`) or made from arrays, ``Mesh(positions, triangles, normals=None,
    name="", label=None, color=None, iso=0.0)``.

    ``positions`` float32 (n, 3), ``normals`` float32 (n, 3) (or (0, 3) without normals) and
    ``triangles`` uint32 (m, 3), counter-clockwise seen from the normals' side: every surface
    merged, as read-only views of the library's buffers (``vertices`` is ``positions``).
    Per surface, in order: ``names``, ``labels`` (a label map's label values, else None),
    ``colors`` (linear RGBA in [0, 1]), ``iso`` (0.0 where none is recorded),
    ``surface_triangles``, ``quantization_steps``
    (Draco's position grid step read from the file, 0 without Draco); :attr:`surfaces` gives them
    as one-surface meshes and ``name``/``label``/``color`` are those of a one-surface mesh.

    Units and axes (``frame``): ``"scan"`` is the scan's physical millimetres in its anatomical
    ``space`` (extracted meshes, arrays, and .drc/.ply/.obj/.stl/.off files); ``"gltf"`` is
    glTF's metres and axes as a .glb/.gltf stores them (+Y superior, +Z anterior, -X the
    patient's right). :meth:`to_scan_frame` undoes the glTF writer's map (the matrix mlfe records
    in the file; RAS's for other glTF files).
    """

    __slots__ = ("_m",)

    def __init__(self, positions, triangles, normals=None, *, name="", label=None, color=(0.8, 0.8, 0.8, 1.0),
                 iso=0.0):
        self._m = _mlfe.make_mesh(positions, triangles, normals, str(name), label,
                                  _numbers("color", color, (3, 4)), float(iso))

    @classmethod
    def _wrap(cls, core):
        mesh = cls.__new__(cls)
        mesh._m = core
        return mesh

    @classmethod
    def join(cls, meshes):
        """One mesh holding the surfaces of ``meshes`` in order (all in the same frame): what a
        multi-node .glb is written from."""
        meshes = list(meshes)
        for m in meshes:
            if not isinstance(m, Mesh):
                raise Error("meshes: expected Mesh objects, got %s" % type(m).__name__)
        return cls._wrap(_mlfe.join_meshes([m._m for m in meshes]))

    positions = property(lambda self: self._m.vertices, doc="float32 (n, 3), every surface merged")
    vertices = positions
    normals = property(lambda self: self._m.normals, doc="float32 (n, 3), or (0, 3) without normals")
    triangles = property(lambda self: self._m.triangles, doc="uint32 (m, 3) indices into positions")
    frame = property(lambda self: "gltf" if self._m.gltf_frame else "scan",
                     doc="'gltf' (metres, glTF's axes) or 'scan' (millimetres in space)")
    units = property(lambda self: "m" if self._m.gltf_frame else "mm")
    space = property(lambda self: self._m.space, doc="'RAS', 'LPS' or '' of the scan frame")
    format = property(lambda self: self._m.format,
                      doc="the file's encoding ('glb', 'gltf', 'drc', 'ply', 'obj', 'stl', 'off'), '' if not read")
    extras = property(lambda self: self._m.extras, doc="the provenance a glTF records (asset.extras), else {}")

    @property
    def iso(self):
        return list(self._m.iso)

    @property
    def surface_triangles(self):
        return list(self._m.surface_triangles)

    @property
    def names(self):
        return list(self._m.names)

    @property
    def labels(self):
        return [e.get("label") if isinstance(e, dict) else None for e in self._m.node_extras]

    @property
    def colors(self):
        # float32 in the library: their shortest spelling, 0.93 rather than 0.9300000071525574
        return [tuple(float(str(np.float32(x))) for x in c) for c in self._m.colors]

    @property
    def quantization_steps(self):
        return list(self._m.quantization_steps)

    @property
    def surfaces(self):
        """The surfaces as one-surface meshes (glTF: one per node), in order."""
        return [Mesh._wrap(self._m.surface(i)) for i in range(self._m.size)]

    def _single(self, values):
        return values[0] if len(values) == 1 else None

    name = property(lambda self: self._single(self.names), doc="the only surface's name (None for several)")
    label = property(lambda self: self._single(self.labels), doc="the only surface's label, or None")
    color = property(lambda self: self._single(self.colors), doc="the only surface's RGBA, or None")

    def to_scan_frame(self):
        """The same surfaces in the scan's millimetres (a copy; ``self`` when already there)."""
        return Mesh._wrap(self._m.to_scan_frame()) if self._m.gltf_frame else self

    @_threaded
    def write(self, path, *, draco=True, quantize=False, tolerance=0.0):
        """Writes the surfaces by extension, as ``mlfe convert`` writes them: .glb/.gltf (one node
        per surface with its name, colour and label; Draco unless ``draco=False``, ``quantize``
        for KHR_mesh_quantization), .drc, .ply, .obj, .stl, .off (one merged mesh). A glTF-frame
        mesh goes back to the scan frame first, so every format gets what the command line
        writes. ``tolerance``: millimetres for Draco/quantization (0: the mesh's own: a tenth of
        the smallest voxel spacing for extracted surfaces, the tolerance a read glTF records or
        half a read .drc's grid step, else 0.01). Atomic: nothing is left behind on error."""
        self._m.write(os.fspath(path), bool(draco), bool(quantize), float(tolerance))

    def __len__(self):
        return len(self._m.triangles)

    def __repr__(self):
        # Names that say more than the writer's default "iso <value>".
        names = self.names
        if all(not n or n == "iso %g" % v for n, v in zip(names, self.iso)):
            names = []
        return "mlfe.Mesh(vertices=%d, triangles=%d, iso=%s%s%s)" % (
            len(self.positions), len(self.triangles), self.iso, ", names=%s" % names if names else "",
            ", frame='gltf' (metres)" if self._m.gltf_frame else "")


@_threaded
def read_mesh(path):
    """Reads every asset format mlfe writes (.glb/.gltf with or without Draco, .drc, .ply, .obj,
    .stl, .off; the kind from the file's contents) as one :class:`Mesh` holding all its surfaces
    (glTF: one per node, with names, colours and labels; MSFT_lod levels are kept for
    :meth:`Mesh.write`, not in the arrays). glTF stays in
    glTF's metres and axes (``frame == 'gltf'``, see :meth:`Mesh.to_scan_frame`); the other formats
    are the scan's millimetres. :func:`read_meshes` gives the surfaces by name."""
    return Mesh._wrap(_mlfe.read_mesh(os.fspath(path)))


def read_meshes(path):
    """The surfaces of :func:`read_mesh` as a dict name → one-surface :class:`Mesh`, in file
    order; an empty or repeated name is made unique as ``'<name> #<position>'`` (from 1)."""
    out = {}
    for i, mesh in enumerate(read_mesh(path).surfaces, 1):
        key = mesh.name
        if not key or key in out:
            key = "%s #%d" % (key, i) if key else "#%d" % i
        out[key] = mesh
    return out


# ---------------------------------------------------------------------------------------------
class Hierarchy:
    """An adaptive approximation: the nested tetrahedral (2D: triangular) hierarchy and the
    function u on its vertices. Made by :func:`build` or :func:`load` (``Hierarchy(path)`` loads
    a ``.mlfeh`` file too).

    ``positions`` are the vertices in the physical frame (millimetres, float64 (n, 3); the
    coarsest cube pads the scan, so some lie beyond it: see :attr:`positions`),
    ``tetrahedra`` the leaf cells as vertex indices (int64 (m, 4), each positively oriented in
    the physical frame, as the .vtu and .msh exports; 2D: ``cells`` (m, 3)),
    ``values`` u at every vertex, ``vertex_levels`` the level each vertex appeared on.
    """

    __slots__ = ("_h",)

    def __init__(self, source):
        path = _fspath(source)
        if path is not None:
            source = _mlfe.load(path)
        elif not isinstance(source, _mlfe.Hierarchy):
            raise Error("Hierarchy: expected a .mlfeh path (or use mlfe.build), got %r" % (source,))
        self._h = source

    dim = property(lambda self: self._h.dim, doc="2 (height field) or 3")
    levels = property(lambda self: self._h.levels, doc="number of refinement levels (the coarsest is 0)")
    vertex_count = property(lambda self: self._h.vertex_count)
    leaf_count = property(lambda self: self._h.leaf_count, doc="leaf cells (tetrahedra in 3D)")
    space = property(lambda self: self._h.space, doc="'RAS', 'LPS' or '' of the physical frame")
    value_range = property(lambda self: tuple(self._h.value_range), doc="the source data's (min, max)")
    stop_reason = property(lambda self: self._h.stop_reason, doc="why refinement stopped (builds)")
    surface_driven = property(lambda self: self._h.surface_driven)
    memory_limited = property(lambda self: self._h.memory_limited)
    @property
    def seconds(self):
        """The build's time in seconds; None for a loaded hierarchy (a file does not keep times,
        so that the same input and options give the same bytes)."""
        return None if self._h.file_info is not None else self._h.seconds

    @property
    def build_record(self):
        """What the build did, as the hierarchy file keeps it (metadata "build"): stop_reason,
        surface_driven, memory_limited, rms_target, noise_sigma, target_from_noise, options,
        per_iteration and surface_passes rows (without times). The same dict for a build and for
        the file it saved; a file written before the record existed gives what it knows
        (empty rows, stop_reason '')."""
        return self._h.build_record
    source = property(lambda self: self._h.source, doc="the input file ('array' for arrays)")

    @property
    def positions(self):
        """Vertex positions in the physical frame (millimetres), float64 (n, 3).

        They can lie outside the scan. A volume's hierarchy is built on the samples' lattice:
        its coarsest mesh is a cube 2^L samples wide along every voxel axis, L the smallest
        level with 2^L >= n - 1 for the longest axis (n samples), starting at the first sample.
        Along voxel axis a (n_a samples, spacing s_a) vertices thus reach up to
        (2^L - (n_a - 1)) * s_a millimetres beyond the last sample, never before the first: a
        181 x 217 x 181 head at 1 mm lies in a 256 mm cube, so up to 76 mm beyond it along x and
        z and 40 mm along y. That padding holds no sample and is not refined (a few large cells);
        assets, exports and renders are clipped to the scan's box."""
        return self._h.positions

    @property
    def cells(self):
        """Leaf cells as vertex indices: int64 (m, 4) tetrahedra in 3D, (m, 3) triangles in 2D."""
        return self._h.cells

    @property
    def tetrahedra(self):
        """Leaf tetrahedra, int64 (m, 4) (3D hierarchies), each positively oriented in the
        physical frame: (p1 - p0) . ((p2 - p0) x (p3 - p0)) > 0, also for a mirrored frame."""
        if self.dim != 3:
            raise Error("tetrahedra: a 2D hierarchy has triangles (use cells)")
        return self._h.cells

    @property
    def values(self):
        """u at every vertex, float64 (n,) (read-only view)."""
        return self._h.values

    @property
    def vertex_levels(self):
        """The level each vertex was created on, uint8 (n,)."""
        return self._h.vertex_levels

    @property
    def frame(self):
        """(spacing, origin, direction rows) of the local → physical map."""
        spacing, origin, direction = self._h.transform
        return tuple(spacing), tuple(origin), np.array(direction).reshape(3, 3)

    @property
    def errors(self):
        """The approximation's error against its data: rms, rms_percent (of the value range),
        l2, psnr_db of the build's last iteration (empty when u was not solved: surface-driven
        builds without a hierarchy output), built here or loaded from a file that keeps its
        build record. A file without the record: what its header holds (norm, rms, max,
        psnr_db, sample_error_bound; None where unknown); :func:`info` gives those for any file."""
        if self._h.file_info is not None and "build" not in self.metadata:
            info = self._h.file_info
            return {k: info[k] for k in ("norm", "rms", "max", "psnr_db", "sample_error_bound")}
        return dict(self._h.errors)

    @property
    def report(self):
        """The JSON report of ``mlfe build --report`` as a dict."""
        return self._h.report

    @property
    def metadata(self):
        """A loaded file's metadata (provenance); {} for a build."""
        info = self._h.file_info
        return {} if info is None else info.get("metadata", {})

    @_threaded
    def extract(self, iso=None, *, progress=None, **options):
        """The iso-surfaces at ``iso`` (a number or a list) as a :class:`Mesh`, extracted as
        ``mlfe iso``/``mlfe convert`` do. Options (the command line's, as keywords): simplify,
        ratio, simplifier, snap, min_component, normals, placement, normals_toward_higher, decimate,
        z_scale, level, surface. A 2D height field needs no iso."""
        isos = _iso_values(iso)
        if isos is None and self.dim == 3:
            raise Error("iso: required for 3D hierarchies (e.g. iso=80 or iso=[80, 150])")
        return Mesh._wrap(self._h.extract(isos or [], progress, **options))

    @_threaded
    def write(self, path, *, iso=None, progress=None, **options):
        """Extracts and writes the surfaces to ``path`` by extension, as ``mlfe iso``; returns
        the asset summary. Options as :meth:`extract` plus tolerance, draco, quantize, lod."""
        isos = _iso_values(iso)
        if isos is None and self.dim == 3:
            raise Error("iso: required for 3D hierarchies (e.g. iso=80 or iso=[80, 150])")
        return self._h.write(os.fspath(path), isos or [], progress, **options)

    def render(self, out=None, *, progress=None, **options):
        """Ray-casts u through the tetrahedral mesh, as ``mlfe render``; see :func:`render`."""
        return render(self, out, progress=progress, **options)

    @_threaded
    def export(self, path, *, level=-1, progress=None):
        """Writes the approximation as ``mlfe export`` does: on the voxel grid it was built from
        (.nii.gz .nii .nrrd .raw .vdb) or as its leaf mesh with values and levels (.vtu .msh), in
        the physical frame; ``level`` uses levels 0..level only (-1: all). Returns the summary
        (written files, counts). A hierarchy built in memory is first saved beside ``path``
        (exact values) and that file exported."""
        out = os.fspath(path)
        if self._h.file_info is not None:
            return _mlfe.export_hierarchy(self.source, out, int(level), progress)
        folder = os.path.dirname(os.path.abspath(out))
        tmp = os.path.join(folder, ".%s.%d.mlfeh" % (os.path.basename(out), os.getpid()))
        try:
            self._h.save(tmp)
            return _mlfe.export_hierarchy(tmp, out, int(level), progress)
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)

    @_threaded
    def save(self, path):
        """Writes the hierarchy file (.mlfeh), as ``mlfe build -o``."""
        self._h.save(os.fspath(path))

    def __repr__(self):
        return "mlfe.Hierarchy(dim=%d, levels=%d, vertices=%d, %s=%d, source=%r)" % (
            self.dim, self.levels, self.vertex_count, "tetrahedra" if self.dim == 3 else "triangles",
            self.leaf_count, self.source)


# ---------------------------------------------------------------------------------------------
@_threaded
def read_volume(path, **options):
    """Reads a volume or height field (vdb, nrrd, nii[.gz], mha/mhd, raw + json, pgm, png) as a
    :class:`Volume` in the file's frame: values float32 indexed ``[i, j, k]`` (a view of the
    library's buffer, no copy); ``info`` holds format, source_type and notes. Options (the
    command line's read options): grid, vec_magnitude, nan_as, space ('ras', 'lps'), and for
    headerless raw data raw_dims, raw_type, raw_endian, raw_spacing, raw_origin, raw_offset;
    zarr_level."""
    values, spacing, origin, info = _mlfe.read_volume(os.fspath(path), **options)
    n = values.ndim
    return Volume(values, spacing=spacing[:n], origin=origin, direction=info["direction"], space=info["space"],
                  info={k: info[k] for k in ("format", "source_type", "notes")})


@_threaded
def load(path):
    """Loads a hierarchy file (.mlfeh) written by ``mlfe build``/``convert --hierarchy`` or
    :meth:`Hierarchy.save`."""
    return Hierarchy(_mlfe.load(os.fspath(path)))


@_threaded
def build(volume, *, iso=None, spacing=None, origin=None, direction=None, affine=None, space=None, progress=None,
          **options):
    """Builds the adaptive approximation of ``volume`` as ``mlfe build`` does: a volume file, a
    tetrahedral mesh with point values (.vtu, .msh), a :class:`Volume`, or an array indexed
    ``[i, j, k]`` with its frame (``affine=`` or spacing/origin/direction/space; see
    :class:`Volume`). Options: rms ('0.5%' or a number in data units), threshold, max_vertices,
    max_level, start_level, norm ('l2', 'h1'), preconditioner, surface_tolerance, check_u,
    max_memory ('50%', '6G', '512M' or bytes). With ``iso`` and no global target, refinement
    follows the surfaces. ``progress``: see the module documentation."""
    _check_iso_dimensions(volume, iso)
    values, frame = _volume_args(volume, spacing, origin, direction, affine, space)
    return Hierarchy(_mlfe.build(values, iso=_iso_values(iso), progress=progress, **frame, **options))


@_threaded
def convert(volume, out, *, iso=None, spacing=None, origin=None, direction=None, affine=None, space=None,
            hierarchy=None, report=None, preview=None, progress=None, **options):
    """Volume in, asset out (.glb .gltf .drc .ply .obj .stl .off), as ``mlfe convert``; returns
    the asset summary (triangles per surface, bytes). ``volume`` as in :func:`build`; build
    options as :func:`build`; asset options: tolerance, draco, quantize, lod, decimate,
    simplify, ratio, simplifier, snap, min_component, normals_toward_higher, normals, placement,
    z_scale, level, surface ('auto', 'samples': marching cubes on the volume's samples,
    'hierarchy': marching tetrahedra on the hierarchy), bricks (extract and simplify in bricks of
    this many samples, a power of two; a raw, NIfTI, NRRD, MetaImage or OME-Zarr file
    with no hierarchy= is then read brick by brick). ``hierarchy=``/``report=``: also write the .mlfeh and the JSON report.
    ``preview=``: also a self-contained HTML page showing the asset (a .glb/.gltf ``out``) in any
    browser with WebGL, opened from disk: orbit controls, the structures with their colours and
    visibility toggles, the report's figures.
    ``labels=True`` (or a list, or '3,7-9'): the volume is a label map; one closed, named
    surface per structure, with label_table, min_component, smooth_iterations, max_offset."""
    _check_iso_dimensions(volume, iso)
    values, frame = _volume_args(volume, spacing, origin, direction, affine, space)
    paths = {k: (None if v is None else os.fspath(v))
             for k, v in (("hierarchy", hierarchy), ("report", report), ("preview", preview))}
    return _mlfe.convert(values, os.fspath(out), iso=_iso_values(iso), progress=progress, **frame, **paths,
                         **options)


# ---------------------------------------------------------------------------------------------
class CompareResult:
    """What :func:`compare` found: ``equal`` (also the truth value), ``kind`` ("mesh", "gltf",
    "image", "volume", "hierarchy" or "mismatch"), ``differences`` as (item, reason) pairs
    (empty when equal within the tolerances), ``notes`` (how the comparison was adjusted: a
    tolerance widened to Draco's quantization step, provenance not compared) and ``report``,
    every measured figure."""

    __slots__ = ("kind", "differences", "report", "notes", "_summary")

    def __init__(self, kind, differences, report, summary, notes=()):
        self.kind = kind
        self.differences = [tuple(d) for d in differences]
        self.report = report
        self.notes = list(notes)
        self._summary = summary

    @property
    def equal(self):
        return not self.differences

    def __bool__(self):
        return self.equal

    def __str__(self):
        return self._summary

    def __repr__(self):
        if self.equal:
            return "mlfe.CompareResult(kind=%r, equal=True)" % self.kind
        return "mlfe.CompareResult(kind=%r, equal=False, differences=%d: %s)" % (
            self.kind, len(self.differences), "; ".join("%s: %s" % d for d in self.differences[:3]))


@_threaded
def compare(expected, actual, **options):
    """Compares two outputs by content, as ``mlfe compare EXPECTED ACTUAL``: files (meshes,
    glTF, EXR/PNG images, volumes, hierarchies; the kind from their contents) or meshes, any mix
    of mesh files and :class:`Mesh` objects. Returns a :class:`CompareResult`.

    Geometry, not provenance: the input's name, the generator and tool, timings and the encoding
    (Draco or not, quantization, file format) are not compared unless ``strict=True``; a Draco
    side widens the tolerances to its quantization step (read from the file; ``notes`` says so).
    Meshes in different frames (a .glb against a :class:`Mesh` in millimetres or a .ply) are
    compared in the scan's millimetres, so the tolerance is then in millimetres.

    Options (the command line's): tolerance (meshes: Hausdorff distance in the meshes' units,
    glTF metres), mean_tolerance, count_tolerance ('2%' or a number of percent), normal_angle
    (degrees), samples, image_max, psnr, value_max, value_rms, number_tolerance, ignore (JSON
    pointers, e.g. ['/asset/extras/note']), strict."""
    if "ignore" in options:
        ignore = options["ignore"]
        options["ignore"] = [ignore] if isinstance(ignore, str) else list(ignore)
    for name, value in (("expected", expected), ("actual", actual)):
        if not isinstance(value, Mesh) and _fspath(value) is None:
            raise Error("%s: expected a file path or a Mesh, got %s" % (name, type(value).__name__))
    if isinstance(expected, Mesh) or isinstance(actual, Mesh):
        sides = [m._m if isinstance(m, Mesh) else os.fspath(m) for m in (expected, actual)]
        return CompareResult(*_mlfe.compare_meshes(*sides, **options))
    return CompareResult(*_mlfe.compare_files(os.fspath(expected), os.fspath(actual), **options))


def read_image(path):
    """Reads an OpenEXR (as ``mlfe render`` writes: half R, G, B, A premultiplied and float Z)
    or PNG image: a dict with ``format``, ``channels`` (name → float32 array (height, width),
    rows from the top; PNG values scaled to [0, 1]), ``types`` (name → "half", "float",
    "uint8", ...) and ``attributes`` (the EXR header's, as text)."""
    fmt, channels, types, attributes = _mlfe.read_image(os.fspath(path))
    return {"format": fmt, "channels": dict(channels), "types": dict(types), "attributes": dict(attributes)}


# ---------------------------------------------------------------------------------------------
# (keyword, documentation) of every render option, from the library's table.
_RENDER_FIELDS = tuple(_mlfe.render_fields())
_RENDER_OPTIONS = tuple(keyword for keyword, _ in _RENDER_FIELDS)


class RenderResult:
    """Images of :func:`render`: ``rgba`` float32 (height, width, 4), premultiplied linear RGBA,
    and ``z`` float32 (height, width), the distance along the view where the accumulated opacity
    reaches ``z_opacity`` (inf where it never does), of the first frame; ``frames`` every frame
    (a dict with rgba, z, exr, png, width, height, seconds, world_to_camera, world_to_ndc);
    ``written`` the files. Rows run from the top, as in the EXR."""

    __slots__ = ("frames", "written", "tetrahedra", "level")

    def __init__(self, raw):
        self.frames = raw["frames"]
        self.written = list(raw["written"])
        self.tetrahedra = raw["tetrahedra"]
        self.level = raw["level"]

    @property
    def rgba(self):
        return self.frames[0]["rgba"]

    @property
    def z(self):
        return self.frames[0]["z"]

    def __repr__(self):
        f = self.frames[0]
        return "mlfe.RenderResult(%dx%d, frames=%d, tetrahedra=%d, written=%s)" % (
            f["width"], f["height"], len(self.frames), self.tetrahedra, self.written)


@_threaded
def render(source, out=None, *, progress=None, **options):
    """Ray-cast images, as ``mlfe render``: ``source`` a :class:`Hierarchy`, a ``.mlfeh`` file,
    a volume (file, :class:`Volume`, array with its frame keywords), built first with the
    build options given, or a tetrahedral mesh with point values (``.vtu``, ``.msh``; ``grid=``
    names the array) rendered as it is, no build. Returns a :class:`RenderResult` with the arrays; with ``out`` (.exr)
    also writes the EXR (half RGBA, float Z, camera and transfer function in the header) and
    with ``png=`` an sRGB preview. Options (the command line's; position, target, up and
    background take three numbers or 'x,y,z', size (w, h) or 'WxH'):
    """
    render_opts = {k: options.pop(k) for k in list(options) if k in _RENDER_OPTIONS}
    _check_png_has_out(render_opts, out)
    if isinstance(source, Hierarchy):
        if options:
            raise Error("%s: not a render option (build options need a volume, not a hierarchy)" % sorted(options)[0])
        h = source
    else:
        path = _fspath(source)
        if path is not None and path.lower().endswith((".vtu", ".msh")):
            grid = options.pop("grid", None)
            if options:
                raise Error("%s: not a render option (a mesh is rendered as it is, not built)" % sorted(options)[0])
            if grid is not None:
                render_opts["grid"] = grid
            return RenderResult(_mlfe.render_mesh(path, None if out is None else os.fspath(out), progress,
                                                  **render_opts))
        if path is not None and path.lower().endswith(".mlfeh"):
            if options:
                raise Error("%s: not a render option (build options need a volume)" % sorted(options)[0])
            h = load(path)
        else:
            h = build(source, progress=progress, **options)
    return RenderResult(_mlfe.render(h._h, None if out is None else os.fspath(out), progress, **render_opts))


def _check_png_has_out(render_opts, out):
    """png= is written beside the EXR: without out= nothing would be written, so it is refused."""
    if render_opts.get("png") is not None and out is None:
        raise Error("png: the PNG is written with the EXR; give out= too (e.g. out='view.exr')")


def _check_iso_dimensions(volume, iso):
    """iso= on a 2D array would silently make a height field: refused."""
    values = volume.values if isinstance(volume, Volume) else None
    if values is None and _fspath(volume) is None and iso is not None:
        values = np.asarray(volume)
    if iso is not None and values is not None and values.ndim == 2:
        raise Error("iso: a 2D array is a height field, which has no iso-surfaces (give a 3D volume, or no iso)")


render.__doc__ += "".join("\n    - ``%s``: %s" % field for field in _RENDER_FIELDS) + "\n"


@_threaded
def export(hierarchy, out, *, level=-1, progress=None):
    """``mlfe export``: a hierarchy (file or :class:`Hierarchy`) on its voxel grid or as its
    leaf mesh; see :meth:`Hierarchy.export`."""
    h = hierarchy if isinstance(hierarchy, Hierarchy) else None
    if h is not None:
        return h.export(out, level=level, progress=progress)
    path = _fspath(hierarchy)
    if path is None:
        raise Error("hierarchy: expected a .mlfeh path or an mlfe.Hierarchy, got %s" % type(hierarchy).__name__)
    return _mlfe.export_hierarchy(path, os.fspath(out), int(level), progress)


def info(source, *, labels=False, label_table=None):
    """What a volume or hierarchy holds, as ``mlfe info --json`` prints it: for a file (read by
    its contents), a dict with format, dims, spacing, origin, direction, space, type, range,
    notes (volumes) or levels, counts per level, error figures, sections (hierarchies);
    ``labels=True`` lists a label map's labels with voxels, mm³ and names. For a
    :class:`Volume` or array: its dims, frame, dtype and range; for a :class:`Hierarchy`: its
    counts, frame and errors."""
    path = _fspath(source)
    if path is not None:
        return _mlfe.info(path, bool(labels), "" if label_table is None else os.fspath(label_table))
    if labels or label_table is not None:
        raise Error("labels: listing labels needs a volume file")
    if isinstance(source, Hierarchy):
        spacing, origin, direction = source.frame
        return {"hierarchy": True, "dim": source.dim, "levels": source.levels, "vertices": source.vertex_count,
                "leaves": source.leaf_count, "spacing": list(spacing), "origin": list(origin),
                "direction": direction.tolist(), "space": source.space, "range": list(source.value_range),
                "errors": source.errors, "source": source.source}
    v = source if isinstance(source, Volume) else Volume(_checked_values("source", source))
    values = v.values
    return {"hierarchy": False, "dim": values.ndim, "dims": list(values.shape), "voxels": int(values.size),
            "type": str(values.dtype), "range": [float(values.min()), float(values.max())] if values.size else [],
            "spacing": list(v.spacing), "origin": list(v.origin), "direction": v.direction.tolist(),
            "space": v.space, "affine": v.affine.tolist(), "memory_bytes": int(values.size) * 4}
