#!/usr/bin/env python3
"""Checks the house's layering: every #include of the project's own headers goes down or
sideways, never up (docs/architecture.md draws the floors).

Units: each room of core/ (its sources and its headers under include/mlfe/core/<room>/),
formats/, converters/ (the pipelines, <mlfe/pipeline.h>, <mlfe/pipeline/...>), converters/cli/
and python/. A room of core/ may include what its room header's "May include:" line names
besides itself; ALLOWED below says it for the units above core. Prints each include that breaks
it (path:line: unit -> unit) and exits 1 if there is one; an include of a header that does
not exist in the tree is reported too (a stale path after a move), and so is an include of
<mlfe/formats/volume_reader.h> inside formats/ other than by its own source (FORMATS_TOP).

Usage: scripts/check_layering.py [ROOT]
"""
import pathlib
import re
import sys

CORE_ROOMS = ("base", "mesh", "field", "fem", "surface", "simplify", "labels", "render")
CORE = {"core/" + r for r in CORE_ROOMS}
# Above core: each may include what is below it. The rooms of core/ say theirs in their room
# header, include/mlfe/core/<room>.h, on its line "// May include: core/base, core/mesh."
ALLOWED = {
    "formats": CORE,
    "converters": CORE | {"formats"},
    "cli": CORE | {"formats", "converters"},
    "python": CORE | {"formats", "converters"},
}
# Inside formats/: read_volume (volume_reader.h) picks a reader through the table of volume
# formats (formats/volume_formats.cpp), so it sits above the readers; only its own source and
# input_files (which asks it a file's format) include it there. The readers take their types
# from volume_read_options.h.
FORMATS_TOP = {"include/mlfe/formats/volume_reader.h": {"formats/volume_reader.cpp", "formats/input_files.cpp"}}
MAY_INCLUDE = re.compile(r"^// May include: (.*)\.$", re.M)


def read_rooms(root):
    """ALLOWED for the rooms of core/, from their room headers."""
    for room in CORE_ROOMS:
        header = root / "include" / "mlfe" / "core" / (room + ".h")
        m = MAY_INCLUDE.search(header.read_text(encoding="utf-8")) if header.is_file() else None
        if not m:
            sys.exit(f"check_layering: {header} has no line '// May include: ...'")
        names = {n.strip() for n in m.group(1).split(",")} - {"nothing of the project"}
        unknown = names - CORE
        if unknown:
            sys.exit(f"check_layering: {header} names unknown rooms {sorted(unknown)}")
        ALLOWED["core/" + room] = names


INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^>"]+)[>"]')


def unit_of_path(rel):
    parts = rel.split("/")
    if parts[0] == "core" and len(parts) > 2:
        return "core/" + parts[1]
    if parts[:3] == ["include", "mlfe", "core"] and len(parts) > 4:
        return "core/" + parts[3]
    if parts[:3] == ["include", "mlfe", "core"] and len(parts) == 4:
        return "core/" + parts[3][:-2]  # the room header, include/mlfe/core/<room>.h
    if parts[0] == "formats" or parts[:3] == ["include", "mlfe", "formats"]:
        return "formats"
    if parts[:2] == ["converters", "cli"]:
        return "cli"
    if parts[0] == "converters" or rel == "include/mlfe/pipeline.h" or parts[:3] == ["include", "mlfe", "pipeline"]:
        return "converters"
    if parts[0] == "python":
        return "python"
    return None


def target_of_include(root, unit, kind, name):
    """(unit, path in the tree) of an include of the project's own, or None for a library's."""
    if kind == "<":
        if not name.startswith("mlfe/") or name in ("mlfe/version.h", "mlfe/mlfe.h"):
            return None
        rel = "include/" + name
    elif unit.startswith("core/") and name.split("/")[0] in CORE_ROOMS:
        rel = "core/" + name  # a room's internal header ("base/morton.h")
    elif name.split("/")[0] in ("formats", "converters"):
        rel = name
    else:
        return None
    return unit_of_path(rel), root / rel


def main():
    root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()
    read_rooms(root)
    bad = 0
    for folder in ("core", "formats", "converters", "python", "include/mlfe"):
        for path in sorted((root / folder).rglob("*")):
            if path.suffix not in (".cpp", ".h"):
                continue
            rel = path.relative_to(root).as_posix()
            unit = unit_of_path(rel)
            if unit is None:
                continue
            for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                m = INCLUDE.match(line)
                if not m:
                    continue
                target = target_of_include(root, unit, m.group(1), m.group(2))
                if target is None:
                    continue
                to, file = target
                if not file.is_file():
                    print(f"{rel}:{n}: {m.group(2)} does not exist")
                    bad += 1
                elif to != unit and to not in ALLOWED[unit]:
                    print(f"{rel}:{n}: {unit} -> {to} ({m.group(2)}) breaks the layering")
                    bad += 1
                elif unit == "formats" and rel not in FORMATS_TOP.get(file.relative_to(root).as_posix(), (rel,)):
                    print(f"{rel}:{n}: formats -> {m.group(2)}, the dispatcher above the readers")
                    bad += 1
    if bad:
        print(f"check_layering: {bad} include(s) out of place (scripts/check_layering.py, docs/architecture.md)")
        return 1
    print("check_layering: every include goes down or sideways")
    return 0


if __name__ == "__main__":
    sys.exit(main())
