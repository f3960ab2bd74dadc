#!/usr/bin/env python3
"""Checks the house rule "no function over 150 lines" in core/, formats/ and converters/.

A function is a brace block opened at namespace or class scope after a header with a '(' (its
signature), from the signature's first line to the closing brace; comments, string literals and
preprocessor lines are ignored, lambdas and blocks inside a function count toward it. Prints every function over the limit
(path:line: name: N lines) and exits 1 if there is one; --list N prints those over N without
failing (to see what is growing toward the limit).

Usage: scripts/check_function_length.py [--limit 150] [--list N] [ROOT]
"""
import argparse
import pathlib
import re
import sys

FOLDERS = ("core", "formats", "converters")
# Over the limit and not split yet (issue #26): reported, not failed on. Remove an entry when its
# function is split; the check fails on an entry that no longer needs to be here.
KNOWN = {
}
SCOPE = re.compile(r"\b(namespace|class|struct|union|enum)\b|extern\s+\"C\"")


def strip(text):
    """Comments and string/char literals blanked out, newlines kept (line numbers stay)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append("\n" * text.count("\n", i, j))
            i = j
        elif text.startswith('R"', i):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            end = text.find(")" + (m.group(1) if m else "") + '"', i)
            j = n if end < 0 else end + len(m.group(1) if m else "") + 2
            out.append('""' + "\n" * text.count("\n", i, j))
            i = j
        elif c in "\"'":
            # A digit separator (1'000'000) is not a character literal.
            if c == "'" and i > 0 and text[i - 1].isalnum() and i + 1 < n and text[i + 1].isalnum():
                out.append(c)
                i += 1
                continue
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            out.append(c + c)
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def without_directives(text):
    """Preprocessor lines (and their continuations) blanked out."""
    lines = text.split("\n")
    directive = False
    for k, l in enumerate(lines):
        if directive or l.lstrip().startswith("#"):
            directive = l.endswith("\\")
            lines[k] = ""
    return "\n".join(lines)


def functions(path):
    """(first line, last line, name) of every function defined in the file."""
    text = without_directives(strip(path.read_text(encoding="utf-8", errors="replace")))
    stack = []  # (kind, start line, name)
    header_start = 0
    found = []
    line = 1
    for i, c in enumerate(text):
        if c == "\n":
            line += 1
        elif c in ";{}":
            if c == "{":
                header = text[header_start:i]
                outer = stack[-1][0] if stack else "scope"
                if SCOPE.search(header) and "(" not in header.split("{")[-1].split("=")[0]:
                    stack.append(("scope", 0, ""))
                elif outer == "scope" and "(" in header:
                    lead = header[: len(header) - len(header.lstrip())]
                    first = line - header.count("\n") + lead.count("\n")
                    name = re.sub(r"\s+", " ", header.strip().split("(")[0]).split(" ")[-1]
                    stack.append(("function", first, name))
                else:
                    stack.append(("block", 0, ""))
            elif c == "}" and stack:
                kind, first, name = stack.pop()
                if kind == "function":
                    found.append((first, line, name))
            header_start = i + 1
    return found


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", nargs="?", default=str(pathlib.Path(__file__).resolve().parent.parent))
    ap.add_argument("--limit", type=int, default=150)
    ap.add_argument("--list", type=int, default=None, help="print functions over N lines, do not fail")
    args = ap.parse_args()
    root = pathlib.Path(args.root)
    bound = args.list if args.list is not None else args.limit
    over, known_seen = [], set()
    for folder in FOLDERS:
        for path in sorted((root / folder).rglob("*")):
            if path.suffix not in (".cpp", ".h", ".hpp", ".cc"):
                continue
            for first, last, name in functions(path):
                length = last - first + 1
                rel = str(path.relative_to(root))
                if length > bound:
                    known = args.list is None and KNOWN.get(rel) == name
                    if known:
                        known_seen.add(rel)
                    over.append((length, f"{rel}:{first}: {name}: {length} lines{' (known)' if known else ''}"))
    for _, text in sorted(over, reverse=True):
        print(text)
    if args.list is not None:
        return 0
    new = [t for _, t in over if not t.endswith("(known)")]
    stale = sorted(set(KNOWN) - known_seen)
    for rel in stale:
        print(f"{rel}: {KNOWN[rel]} is within the limit now: remove it from KNOWN", file=sys.stderr)
    if new:
        print(f"{len(new)} function(s) over {args.limit} lines: split them into named steps", file=sys.stderr)
    return 1 if new or stale else 0


if __name__ == "__main__":
    sys.exit(main())
