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
- Resumable: a scan is skipped when its outputs all exist (outputs appear atomically, so an
  existing file is a finished one) and its record, ``<out_dir>/<stem>.mlfe-batch`` (written
  after the outputs), holds the same options, iso-values and outputs, the same mlfe version, and
  the same size and modification time of every file the scan's read opens. Anything else
  converts it again, as does ``overwrite=True``.
- Options are checked once, before any scan is sent: a misspelt keyword or a value out of
  range raises :class:`mlfe.Error` at once (with the nearest keyword), as :func:`mlfe.convert`
  would on every scan.
- Failures: a scan that fails (unreadable file, bad values, a crashed worker) gets a ``failed``
  row with its message; the others go on.
- Summary: ``<out_dir>/<summary>.csv`` and ``.json``: one row per scan (input, status
  converted/skipped/failed, outputs, asset_triangles, asset_vertices and asset_bytes of the
  asset written, hierarchy_vertices of the hierarchy built (from the report; empty without
  report or for label maps), seconds, message).

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

_COLUMNS = ("input", "status", "outputs", "asset_triangles", "asset_vertices", "asset_bytes", "hierarchy_vertices",
            "seconds", "message")
_FIGURES = ("asset_triangles", "asset_vertices", "asset_bytes", "hierarchy_vertices")
_RECORD_SUFFIX = ".mlfe-batch"  # never a report's (.json) nor an asset's ending


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


def _row(path, status, outs, message="", figures=None, seconds=None):
    figures = figures or {}
    row = {"input": path, "status": status, "outputs": ";".join(outs.values())}
    row.update({k: figures.get(k) for k in _FIGURES})
    row.update({"seconds": None if seconds is None else round(seconds, 3), "message": message})
    return row


def _asset_figures(summary):
    """asset_triangles, asset_vertices, asset_bytes of convert's asset summary (iso-surfaces per
    surface, label maps per structure)."""
    parts = summary.get("surfaces") or summary.get("structures") or []
    vertices = [p.get("vertices") for p in parts]
    return {"asset_triangles": summary.get("triangles"), "asset_bytes": summary.get("bytes"),
            "asset_vertices": sum(vertices) if vertices and None not in vertices else None}


def _report_figures(outs):
    """The figures of an existing report (a skipped scan), if any: the asset's, and the
    hierarchy's vertices."""
    try:
        with open(outs["report"]) as f:
            r = json.load(f)
        return dict(_asset_figures(r.get("asset", {})), hierarchy_vertices=r.get("vertices"))
    except (KeyError, OSError, ValueError, AttributeError):
        return {}


def _record_path(outs):
    return os.path.splitext(outs["asset"])[0] + _RECORD_SUFFIX


def _jsonable(value):
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if hasattr(value, "tolist"):  # NumPy arrays and scalars
        return value.tolist()
    return repr(value)


def _record(path, outs, iso, options):
    """What a scan's outputs were made from: the options, iso-values and outputs, the mlfe
    version, and size and modification time of every file the scan's read opens; as JSON
    reads it back (so that it compares equal to a stored one)."""
    # threads= changes no output byte.
    options = {k: v for k, v in options.items() if k != "threads"}
    files = []
    for f in mlfe._mlfe.input_files(path):
        st = os.stat(f)
        files.append([os.path.abspath(f), st.st_size, st.st_mtime_ns])
    record = {"mlfe": mlfe.__version__, "input": files, "iso": iso, "options": options,
              "outputs": sorted(os.path.basename(o) for o in outs.values())}
    return json.loads(json.dumps(record, sort_keys=True, default=_jsonable))


def _up_to_date(path, outs, iso, options):
    """Whether a scan's outputs all exist and its record matches the scan and the options."""
    if not all(os.path.exists(o) for o in outs.values()):
        return False
    try:
        with open(_record_path(outs)) as f:
            stored = json.load(f)
        return stored == _record(path, outs, iso, options)
    except (OSError, ValueError, mlfe.Error):
        return False


def _convert_one(path, outs, iso, options):
    """One scan on a worker: mlfe.convert with the batch's options, then the scan's record;
    never raises."""
    start = time.perf_counter()
    record_path = _record_path(outs)
    try:
        for o in outs.values():
            os.makedirs(os.path.dirname(o) or ".", exist_ok=True)
        # An old record must not vouch for outputs this run may leave half replaced.
        if os.path.exists(record_path):
            os.remove(record_path)
        try:  # before the read: what the outputs come from
            record = _record(path, outs, iso, options)
        except (OSError, mlfe.Error):  # no record; convert names what is wrong with the scan
            record = None
        summary = mlfe.convert(path, outs["asset"], iso=iso, hierarchy=outs.get("hierarchy"),
                               report=outs.get("report"), **options)
        figures = _asset_figures(summary)
        if "report" in outs:
            figures["hierarchy_vertices"] = _report_figures(outs).get("hierarchy_vertices")
        if record is not None:
            tmp = record_path + ".part"
            with open(tmp, "w") as f:
                json.dump(record, f, sort_keys=True, indent=1)
            os.replace(tmp, record_path)
        return _row(path, "converted", outs, figures=figures, seconds=time.perf_counter() - start)
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
    for key in ("hierarchy", "report", "out", "preview"):
        if key in options:
            raise mlfe.Error("%s: the batch names each scan's outputs (see hierarchy=True, report=True)" % key)
    for key in ("spacing", "origin", "direction", "affine", "space", "progress"):
        if key in options:
            raise mlfe.Error("%s: not a batch option (scan files bring their own frame; on_row reports progress)"
                             % key)
    iso = mlfe._iso_values(iso)
    # Once here, not on every scan of the cluster.
    checked = dict(options)
    if checked.get("threads") is not None:
        mlfe._thread_limit(checked.pop("threads"))
    checked.pop("threads", None)
    mlfe._mlfe.check_convert_keywords(iso, bool(hierarchy), **checked)
    out_dir = os.fspath(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    plan = _plan(inputs, out_dir, asset_ext, hierarchy, report)

    rows = {}
    todo = []
    for path, outs in plan:
        if not overwrite and _up_to_date(path, outs, iso, options):
            rows[path] = _row(path, "skipped", outs, figures=_report_figures(outs) if report else None)
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
