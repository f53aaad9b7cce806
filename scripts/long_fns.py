#!/usr/bin/env python3
"""Lists every function in src/ longer than a limit (default 100 lines), tests excluded.

A function runs from its `fn` line to the closing brace at its own indentation (rustfmt
layout). `#[cfg(test)]` modules and `tests.rs` files are skipped. Exits 1 if any is listed.
Usage: scripts/long_fns.py [LIMIT]
"""
import pathlib
import re
import sys

LIMIT = int(sys.argv[1]) if len(sys.argv) > 1 else 100
FN = re.compile(r"^(\s*)(pub(\([^)]*\))? )?(const )?(unsafe )?fn (\w+)")


def long_fns(path):
    lines = path.read_text().split("\n")
    skip_from = len(lines)
    for i, line in enumerate(lines):
        if line.startswith("#[cfg(test)]") and i + 1 < len(lines) and lines[i + 1].startswith("mod "):
            skip_from = i
            break
    for i, line in enumerate(lines[:skip_from]):
        m = FN.match(line)
        if not m:
            continue
        indent = m.group(1)
        j = i
        while j < len(lines) and not lines[j].rstrip().endswith(("{", ";")):
            j += 1
        if j < len(lines) and lines[j].rstrip().endswith(";") and "{" not in lines[j]:
            continue  # a declaration without a body
        close = indent + "}"
        end = next((k for k in range(i + 1, len(lines)) if lines[k] == close), None)
        if end is not None and end - i + 1 > LIMIT:
            yield i + 1, m.group(6), end - i + 1


found = False
for path in sorted(pathlib.Path("src").rglob("*.rs")):
    if path.name == "tests.rs":
        continue
    for line, name, n in long_fns(path):
        print(f"{path}:{line}: {name} is {n} lines")
        found = True
sys.exit(1 if found else 0)
