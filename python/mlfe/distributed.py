"""One volume converted on Dask workers (``distributed``): the bricks of ``mlfe convert`` read and
simplified on the workers, the seams and the writing on the client, the command line's bytes.

    import mlfe.distributed
    mlfe.distributed.convert("big.zarr", "big.glb", iso=80)       # a LocalCluster on this machine
    client = distributed.Client("tcp://scheduler:8786")           # or any running scheduler
    mlfe.distributed.convert("/shared/big.zarr", "big.glb", client=client, iso=80)

- What runs where: the client opens the volume (its header only, for the formats read box by box),
  resolves and checks the options as ``mlfe convert`` does (a bad keyword raises here, before
  any task) and sends groups of bricks to the workers; each task opens the volume itself, reads
  and simplifies its bricks and returns their meshes as bytes. The seams are joined on the
  workers too, over the command line's tree of slabs (a slab: the bricks with the same z index;
  a leaf task joins one slab's bricks, a node task its two halves); the client joins the root's
  two halves and writes the asset.
- Paths: every worker reads the input by the same path as the client (one machine, or a shared
  file system); only the client writes, so the output folder need only exist there. Workers
  need this package (the same version) importable.
- Bricks: ``bricks=N`` (a power of two), or by default the command line's auto rule: 128-sample
  bricks for a volume read box by box over 2^27 samples. With options under which ``mlfe
  convert`` reads the volume whole (a smaller volume with auto bricks, LODs, ``level``,
  ``min_component``, a global target) there is nothing to distribute: it raises (use
  :func:`mlfe.convert`). Raw, NIfTI, NRRD, MetaImage files and OME-Zarr stores are read
  brick by brick (NRRD's bzip2, ascii and hex encodings excepted); any other volume is read whole
  by each task, so it gets one task per worker thread.
- Errors: a worker's error raises on the client as the same :class:`mlfe.Error` with the same
  message as the local call; no output is written.
- Progress: ``progress(fraction, stage)`` as in :func:`mlfe.convert`, the fraction counting the
  bricks done ("extracting", up to 0.9), then "writing"; returning ``False`` cancels
  (:class:`mlfe.Cancelled`), as do an exception raised by the callback and Ctrl-C (raised as
  they are): the pending tasks are cancelled and no output is written.
"""
from __future__ import annotations

import os

import mlfe
from mlfe import _mlfe
from mlfe.batch import _client

__all__ = ["convert"]

# Groups of bricks per worker thread for a volume read brick by brick: enough that the threads
# stay busy however unequal the bricks, few enough that a task (several bricks) outweighs its
# scheduling.
_TASKS_PER_THREAD = 4

# The keywords of mlfe.convert whose outputs need the whole volume or a hierarchy.
_LOCAL_ONLY = ("hierarchy", "report", "labels", "render")


def _parts(input, iso, options, first, last):
    """On a worker: the encoded parts of bricks [first, last), in brick order."""
    return _mlfe.open_bricks(input, None, iso, **options).parts(first, last)


def _join_slab(input, iso, options, slab, groups):
    """On a worker: the encoded join of slab ``slab`` from ``groups``, (parts of bricks [first,
    last), first, last) overlapping it."""
    job = _mlfe.open_bricks(input, None, iso, **options)
    lo, hi = slab * job.slab_bricks, (slab + 1) * job.slab_bricks
    parts = []
    for group, first, last in groups:
        parts.extend(group[max(lo, first) - first:min(hi, last) - first])
    return job.join(slab, slab + 1, parts)


def _join_halves(input, iso, options, first, end, low, high):
    """On a worker: the encoded join of slabs [first, end) from its halves' pieces."""
    return _mlfe.open_bricks(input, None, iso, **options).join(first, end, [low, high])


def _groups(count, tasks):
    """``tasks`` (at most ``count``) contiguous [first, last) ranges covering ``count`` bricks,
    their sizes differing by at most one."""
    tasks = max(1, min(count, tasks))
    return [(count * g // tasks, count * (g + 1) // tasks) for g in range(tasks)]


def _brick_groups(job, tasks):
    """About ``tasks`` groups of bricks: within slabs for a volume read brick by brick (a slab's
    join then waits for its own bricks only), across them for one read whole by each task."""
    if not job.streamed:
        return _groups(job.count, tasks)
    per_slab = -(-tasks // job.slabs)
    return [(s * job.slab_bricks + first, s * job.slab_bricks + last)
            for s in range(job.slabs) for first, last in _groups(job.slab_bricks, per_slab)]


def _submit_tree(submit, job, groups):
    """The futures of the root's halves (of the root itself for one slab): each node joined by a
    task from its bricks' groups (a slab) or its halves, as the command line's tree."""
    def node(first, end):
        if end == first + 1:
            lo, hi = first * job.slab_bricks, end * job.slab_bricks
            return submit(_join_slab, first, [(f, a, b) for (a, b), f in groups if a < hi and b > lo])
        split = job.split(first, end)
        return submit(_join_halves, first, end, node(first, split), node(split, end))

    if job.slabs == 1:
        return [node(0, 1)]
    split = job.split(0, job.slabs)
    return [node(0, split), node(split, job.slabs)]


def _report(progress, fraction, stage, final=False):
    """Calls ``progress`` as the library does: a falsy answer other than None cancels, except at
    the final report (the output exists by then)."""
    if progress is None:
        return
    answer = progress(fraction, stage)
    if not final and answer is not None and not answer:
        raise mlfe.Cancelled("cancelled")


def convert(input, output, client=None, *, iso=None, progress=None, n_workers=None, **options):
    """Converts the volume file ``input`` to the asset ``output`` (.glb .gltf .drc .ply .obj
    .stl .off) with its bricks computed on Dask workers; returns the asset summary. ``client``:
    None (a LocalCluster of ``n_workers`` processes, one thread each, closed afterwards), a
    scheduler address or a ``distributed.Client``. ``iso``, the build, asset and read options
    (``bricks``, ``simplify``, ``ratio``, ``max_memory``, ``zarr_level``, ``raw_dims``, ...) as
    :func:`mlfe.convert` and the command line; the bytes are those of ``mlfe convert`` with the
    same options. See the module documentation for paths, bricks, errors and progress."""
    for key in _LOCAL_ONLY:
        if key in options:
            raise mlfe.Error("%s: mlfe.distributed writes the asset alone (use mlfe.convert)" % key)
    if progress is not None and not callable(progress):
        raise mlfe.Error("progress: expected a callable (fraction, stage), got %s" % type(progress))
    input, output = os.fspath(input), os.fspath(output)
    iso = mlfe._iso_values(iso)
    if iso is None:  # else the volume would be refused as not read in bricks (no iso: a global target)
        raise mlfe.Error("iso: required for 3D volumes (e.g. iso=80 or iso=[80, 150])")
    job = _mlfe.open_bricks(input, output, iso, **options)
    options = dict(options, bricks=job.edge)  # auto resolved once, here

    import distributed

    dask_client, close = _client(client, n_workers)
    try:
        threads = max(1, sum(dask_client.nthreads().values()))
        ranges = _brick_groups(job, threads * (_TASKS_PER_THREAD if job.streamed else 1))
        futures = {dask_client.submit(_parts, input, iso, options, first, last, pure=False): (first, last)
                   for first, last in ranges}

        def submit(function, *args):
            return dask_client.submit(function, input, iso, options, *args, pure=False)

        # Only the root's halves and the pending groups are held here, so every other piece is
        # released on its worker once its parent's task has it.
        halves = _submit_tree(submit, job, [(futures[f], f) for f in futures])
        done = 0
        try:
            _report(progress, 0.0, "extracting")
            for future in distributed.as_completed(list(futures)):
                first, last = futures.pop(future)
                if future.status == "error":
                    future.result()  # raises the worker's error (a done group's parts stay there)
                done += last - first
                _report(progress, 0.9 * done / job.count, "extracting")
            pieces = [h.result() for h in halves]
            halves = []
        finally:
            if futures or halves:
                dask_client.cancel(list(futures) + halves)
    finally:
        for c in close:
            c.close()
    _report(progress, 0.9, "writing")
    summary = job.write(output, pieces)  # empties `pieces`: the meshes are held once while joined
    _report(progress, 1.0, "writing", final=True)
    return summary
