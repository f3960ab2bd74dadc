"""Batch conversion of many scans on Dask (``distributed``): a study folder or a list of scans
in, per scan the outputs ``mlfe convert`` writes, and a summary table (CSV and JSON) out.

    import mlfe.batch
    result = mlfe.batch.convert("study/", "assets/", iso=[300, 1200], hierarchy=True)
    print(result.failed)          # [(input, message), ...]

- Where: a ``LocalCluster`` on this machine by default (``n_workers`` processes, one thread
  each: the library runs its own threads inside a scan), or any running scheduler
  (``scheduler="tcp://host:8786"``) or an existing ``distributed.Client``. Workers need this
  package and read the inputs by the same paths, and write to ``out_dir``.
- Names: ``<out_dir>/<stem><asset_ext>`` (``.glb`` by default), with ``hierarchy=True`` also
  ``<stem>.mlfeh`` and with ``report=True`` (default) ``<stem>.json``, the files
  ``mlfe convert in -o <stem>.glb --hierarchy <stem>.mlfeh --report <stem>.json`` writes with the
  same options (keywords as in :func:`mlfe.convert`). Scans found in sub-folders keep their
  relative folder under ``out_dir``.
- Resumable: a scan whose outputs all exist is skipped (outputs appear atomically, so an
  existing file is a finished one); ``overwrite=True`` converts it again.
- Failures: a scan that fails (unreadable file, bad values, a crashed worker) gets a ``failed``
  row with its message; the others go on.
- Summary: ``<out_dir>/<summary>.csv`` and ``.json``: one row per scan (input, status
  converted/skipped/failed, outputs, triangles, bytes, vertices, seconds, message).

Memory: each scan may use ``max_memory`` (half the RAM by default, as the command line); with
several workers on one machine pass e.g. ``max_memory="20%"``.
"""
from __future__ import annotations

import csv
import json
import os
import time

import mlfe

__all__ = ["BatchResult", "convert", "find_scans", "VOLUME_SUFFIXES"]

#: File name endings read as scans when a folder is given (lower case): the volume files that are
#: a scan by themselves and the tetrahedral meshes, from the library's table of formats.
VOLUME_SUFFIXES = tuple(mlfe._mlfe.scan_extensions())

_COLUMNS = ("input", "status", "outputs", "triangles", "bytes", "vertices", "seconds", "message")


def find_scans(folder, recursive=True):
    """The scans in ``folder`` (names ending in one of VOLUME_SUFFIXES), sorted."""
    found = []
    for root, dirs, files in os.walk(folder):
        dirs.sort()
        found += [os.path.join(root, f) for f in sorted(files) if _suffix(f)]
        if not recursive:
            break
    return found


def _suffix(name):
    low = name.lower()
    return next((s for s in VOLUME_SUFFIXES if low.endswith(s)), None)


def _stem(path):
    name = os.path.basename(path)
    suffix = _suffix(name)
    if suffix:
        return name[: -len(suffix)]
    return os.path.splitext(name)[0]


class BatchResult:
    """The rows of a batch (dicts with the summary's columns) and the summary files."""

    def __init__(self, rows, csv_path, json_path):
        self.rows = rows
        self.csv_path = csv_path
        self.json_path = json_path

    @property
    def failed(self):
        """(input, message) of every failed scan."""
        return [(r["input"], r["message"]) for r in self.rows if r["status"] == "failed"]

    def count(self, status):
        return sum(1 for r in self.rows if r["status"] == status)

    def __repr__(self):
        return "mlfe.batch.BatchResult(converted=%d, skipped=%d, failed=%d, summary=%r)" % (
            self.count("converted"), self.count("skipped"), self.count("failed"), self.csv_path)


def _plan(inputs, out_dir, asset_ext, hierarchy, report):
    """(input, {kind: output path}) per scan; checks that no two scans share an output."""
    if isinstance(inputs, (str, os.PathLike)):
        folder = os.fspath(inputs)
        if not os.path.isdir(folder):
            raise mlfe.Error("inputs: %s is not a folder (give a folder or a list of scans)" % folder)
        scans = [(p, os.path.relpath(os.path.dirname(p), folder)) for p in find_scans(folder)]
    else:
        scans = [(os.fspath(p), ".") for p in inputs]
    plan, owner = [], {}
    for path, rel in scans:
        base = os.path.normpath(os.path.join(out_dir, rel, _stem(path)))
        outs = {"asset": base + asset_ext}
        if hierarchy:
            outs["hierarchy"] = base + ".mlfeh"
        if report:
            outs["report"] = base + ".json"
        for o in outs.values():
            if o in owner:
                raise mlfe.Error("inputs: %s and %s would both write %s" % (owner[o], path, o))
            owner[o] = path
        plan.append((path, outs))
    return plan


def _row(path, status, outs, message="", summary=None, seconds=None):
    summary = summary or {}
    return {
        "input": path,
        "status": status,
        "outputs": ";".join(outs.values()),
        "triangles": summary.get("triangles"),
        "bytes": summary.get("bytes"),
        "vertices": summary.get("vertices"),
        "seconds": None if seconds is None else round(seconds, 3),
        "message": message,
    }


def _report_figures(outs):
    """triangles, bytes, vertices from an existing report (a skipped scan), if any."""
    try:
        with open(outs["report"]) as f:
            r = json.load(f)
        asset = r.get("asset", {})
        return {"triangles": asset.get("triangles"), "bytes": asset.get("bytes"), "vertices": r.get("vertices")}
    except (KeyError, OSError, ValueError):
        return {}


def _convert_one(path, outs, iso, options):
    """One scan on a worker: mlfe.convert with the batch's options; never raises."""
    start = time.perf_counter()
    try:
        for o in outs.values():
            os.makedirs(os.path.dirname(o) or ".", exist_ok=True)
        summary = mlfe.convert(path, outs["asset"], iso=iso, hierarchy=outs.get("hierarchy"),
                               report=outs.get("report"), **options)
        figures = {"triangles": summary.get("triangles"), "bytes": summary.get("bytes")}
        if "report" in outs:
            figures["vertices"] = _report_figures(outs).get("vertices")
        return _row(path, "converted", outs, summary=figures, seconds=time.perf_counter() - start)
    except Exception as e:  # every failure becomes the scan's row, whatever raised it
        message = str(e).splitlines()[0] if str(e) else type(e).__name__
        return _row(path, "failed", outs, message=message, seconds=time.perf_counter() - start)


def _client(scheduler, n_workers):
    """(client, things to close): an existing Client, a scheduler address, or a LocalCluster."""
    import distributed

    if isinstance(scheduler, distributed.Client):
        return scheduler, []
    if scheduler is not None:
        client = distributed.Client(scheduler)
        return client, [client]
    cluster = distributed.LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
    client = distributed.Client(cluster)
    return client, [client, cluster]


def _write_summary(rows, base):
    csv_path, json_path = base + ".csv", base + ".json"
    tmp = csv_path + ".part"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=_COLUMNS)
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, csv_path)
    tmp = json_path + ".part"
    with open(tmp, "w") as f:
        json.dump({"scans": rows, "converted": sum(r["status"] == "converted" for r in rows),
                   "skipped": sum(r["status"] == "skipped" for r in rows),
                   "failed": sum(r["status"] == "failed" for r in rows)}, f, indent=1)
    os.replace(tmp, json_path)
    return csv_path, json_path


def convert(inputs, out_dir, *, iso=None, asset_ext=".glb", hierarchy=False, report=True, scheduler=None,
            n_workers=None, overwrite=False, summary="batch_summary", on_row=None, **options):
    """Converts every scan of ``inputs`` (a folder, searched recursively, or a list of paths)
    into ``out_dir`` on Dask; returns a :class:`BatchResult`. ``iso`` and ``options`` as
    :func:`mlfe.convert` (the same for every scan); ``asset_ext`` the asset type (.glb .gltf
    .drc .ply .obj .stl .off); ``scheduler`` None (a LocalCluster of ``n_workers`` processes),
    an address or a ``distributed.Client``; ``on_row(row)`` is called as each scan finishes.
    See the module documentation for names, resuming and the summary."""
    if asset_ext.lower() not in mlfe._mlfe.asset_extensions:
        raise mlfe.Error("asset_ext: expected %s, got %r" % (" ".join(mlfe._mlfe.asset_extensions), asset_ext))
    for key in ("hierarchy", "report", "out"):
        if key in options:
            raise mlfe.Error("%s: the batch names each scan's outputs (see hierarchy=True, report=True)" % key)
    iso = mlfe._iso_values(iso)
    out_dir = os.fspath(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    plan = _plan(inputs, out_dir, asset_ext, hierarchy, report)

    rows = {}
    todo = []
    for path, outs in plan:
        if not overwrite and all(os.path.exists(o) for o in outs.values()):
            rows[path] = _row(path, "skipped", outs, summary=_report_figures(outs) if report else None)
            if on_row:
                on_row(rows[path])
        else:
            todo.append((path, outs))

    if todo:
        import distributed

        client, close = _client(scheduler, n_workers)
        try:
            futures = {client.submit(_convert_one, p, o, iso, options, pure=False, key="mlfe-" + p + "-" +
                                     str(time.time_ns())): (p, o) for p, o in todo}
            for future in distributed.as_completed(futures):
                path, outs = futures[future]
                try:
                    rows[path] = future.result()
                except Exception as e:  # the worker died (KilledWorker) or the task was lost
                    rows[path] = _row(path, "failed", outs, message="%s: %s" % (type(e).__name__, e))
                if on_row:
                    on_row(rows[path])
        finally:
            for c in close:
                c.close()

    ordered = [rows[p] for p, _ in plan]
    csv_path, json_path = _write_summary(ordered, os.path.join(out_dir, summary))
    return BatchResult(ordered, csv_path, json_path)
