#!/usr/bin/env python3
"""The import rule of docs/design.md §8, checked: the library's top-level modules (src/*, the
binary's src/cli and src/figures left out) import each other without a cycle. Reads the
`crate::name` paths of every non-comment, non-test line; prints the cycles, exit 1 if any."""
import os
import re
import sys

root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src")
deps = {}
for dirpath, _, files in os.walk(root):
    rel_dir = os.path.relpath(dirpath, root)
    if rel_dir.split(os.sep)[0] in ("cli", "figures"):
        continue
    for f in files:
        if not f.endswith(".rs") or (rel_dir == "." and f in ("main.rs", "lib.rs")):
            continue
        rel = os.path.normpath(os.path.join(rel_dir, f))
        top = rel.split(os.sep)[0].removesuffix(".rs")
        code = open(os.path.join(dirpath, f)).read().split("#[cfg(test)]\nmod tests")[0]
        used = deps.setdefault(top, set())
        for line in code.splitlines():
            if not line.strip().startswith("//"):
                used.update(m for m in re.findall(r"crate::(\w+)", line) if m != top)


def reach(a, seen):
    for b in deps.get(a, ()):
        if b not in seen:
            seen.add(b)
            reach(b, seen)
    return seen


cycles = sorted({tuple(sorted((a, b))) for a in deps for b in deps[a] if a in reach(b, set())})
print(f"{len(deps)} top-level modules; cycles: {cycles if cycles else 'none'}")
sys.exit(1 if cycles else 0)
