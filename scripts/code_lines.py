#!/usr/bin/env python3
"""Counts code lines under a source folder: lines that are neither blank nor comments, outside
`#[cfg(test)]` items and files only tests include (`#[cfg(test)] mod name;`).

Usage: scripts/code_lines.py [DIR] [--exclude SUBDIR]... [--per-file]
e.g.   scripts/code_lines.py src/level --exclude ml --per-file
"""
import os
import re
import sys


def test_only_files(path, text):
    """Files declared by `#[cfg(test)] mod name;` in `path`."""
    here = os.path.dirname(path)
    base = os.path.basename(path)
    if base not in ("mod.rs", "lib.rs", "main.rs"):
        here = os.path.join(here, base[:-3])
    out = set()
    for m in re.finditer(r"#\[cfg\(test\)\]\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;", text):
        name = m.group(1)
        out.add(os.path.normpath(os.path.join(here, name + ".rs")))
        out.add(os.path.normpath(os.path.join(here, name, "mod.rs")))
    return out


def strip_strings(line):
    return re.sub(r'"(?:\\.|[^"\\])*"', '""', line)


def count(text):
    n = 0
    skip_depth = None  # brace depth at which a #[cfg(test)] item started
    pending = False  # saw #[cfg(test)], item not yet opened
    depth = 0
    in_block = False
    for raw in text.splitlines():
        line = raw.strip()
        if in_block:
            if "*/" in line:
                in_block = False
                line = line.split("*/", 1)[1].strip()
            else:
                continue
        if line.startswith("/*"):
            if "*/" not in line:
                in_block = True
            continue
        if not line or line.startswith("//"):
            continue
        code = strip_strings(line).split("//", 1)[0]
        if skip_depth is None and not pending and code.startswith("#[cfg(test)]"):
            pending = True
            rest = code[len("#[cfg(test)]"):].strip()
            if not rest:
                continue
            code = rest
        opens, closes = code.count("{"), code.count("}")
        if pending:
            if opens:
                skip_depth = depth
                pending = False
            elif code.endswith(";"):
                pending = False
                depth += opens - closes
                continue
        depth += opens - closes
        if skip_depth is not None:
            if depth <= skip_depth:
                skip_depth = None
            continue
        n += 1
    return n


def main():
    args = sys.argv[1:]
    per_file = "--per-file" in args
    args = [a for a in args if a != "--per-file"]
    excludes = []
    while "--exclude" in args:
        i = args.index("--exclude")
        excludes.append(args[i + 1])
        del args[i : i + 2]
    root = args[0] if args else "src/level"
    files = []
    for d, _, names in os.walk(root):
        rel = os.path.relpath(d, root)
        if any(rel == e or rel.startswith(e + os.sep) for e in excludes):
            continue
        files += [os.path.normpath(os.path.join(d, f)) for f in names if f.endswith(".rs")]
    texts = {f: open(f).read() for f in files}
    tests = set()
    for f, t in texts.items():
        tests |= test_only_files(f, t)
    total = 0
    rows = []
    for f in sorted(files):
        if f in tests:
            continue
        c = count(texts[f])
        total += c
        rows.append((c, f))
    if per_file:
        for c, f in sorted(rows):
            print(f"{c:6} {f}")
    print(f"{total:6} total")


main()
