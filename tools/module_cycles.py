#!/usr/bin/env python3
"""List the import circles among the Rust core's files.

An edge a -> b is a path `crate::...`, `super::...` or `self::...` in file a (in a `use` or inline) that names
an item of file b. A module's edges to its own submodules (its `mod` declarations and re-exports) are left
out: a circle is files that reach each other through their siblings or other folders. Prints the edges of
each circle (a strongly connected component of more than one file) and exits 1 when there is one.

    python3 tools/module_cycles.py [--edges]
"""

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent / "rust"
PATH = re.compile(r"\b(crate|super|self)((?:::(?:\{[^{}]*(?:\{[^{}]*\}[^{}]*)*\}|\w+))+)")


def module_of(file):
    """The module path of a file: rust/fitness/mod.rs -> ('fitness',), rust/lib.rs -> ()."""
    parts = list(file.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] in ("mod", "lib"):
        parts.pop()
    return tuple(parts)


def expand(tail):
    """`::a::{b, c::{d, e}}` -> [[a, b], [a, c, d], [a, c, e]]."""
    tail = tail.lstrip(":")
    if not tail:
        return [[]]
    if tail.startswith("{"):
        depth, items, start = 0, [], 1
        for i, ch in enumerate(tail):
            if ch == "{":
                depth += 1
            elif ch == "}":
                depth -= 1
                if depth == 0:
                    items.append(tail[start:i])
                    break
            elif ch == "," and depth == 1:
                items.append(tail[start:i])
                start = i + 1
        out = []
        for item in items:
            item = item.strip().split(" as ")[0].strip()
            if item:
                out.extend(expand(item))
        return out
    head, _, rest = tail.partition("::")
    return [[head] + p for p in expand(rest)]


def strip_comments(text):
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return re.sub(r"//[^\n]*", "", text)


def main():
    files = sorted(ROOT.rglob("*.rs"))
    by_module = {module_of(f): f for f in files}
    edges = {}
    for f in files:
        mod = module_of(f)
        own_dir = f.name in ("mod.rs", "lib.rs")
        for m in PATH.finditer(strip_comments(f.read_text())):
            kind, tail = m.group(1), m.group(2)
            if kind == "crate":
                base = ()
            elif kind == "super":
                base = mod[:-1] if own_dir else mod[:-1]
                # `super::super::x`
                while tail.startswith("::super"):
                    tail = tail[len("::super"):]
                    base = base[:-1]
            else:
                base = mod
            for path in expand(tail):
                full = base + tuple(p for p in path if p != "self")
                # The longest prefix naming a file.
                target = next(
                    (by_module[full[:n]] for n in range(len(full), -1, -1) if full[:n] in by_module), None
                )
                if target is None or target == f:
                    continue
                tmod = module_of(target)
                if len(tmod) > len(mod) and tmod[: len(mod)] == mod:
                    continue  # a module's own submodule
                edges.setdefault(f, set()).add(target)

    rel = lambda f: str(f.relative_to(ROOT))
    if "--edges" in sys.argv:
        for a in sorted(edges):
            for b in sorted(edges[a]):
                print(f"{rel(a)} -> {rel(b)}")

    # Tarjan's strongly connected components.
    index, low, stack, on, comps = {}, {}, [], set(), []
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))

    for v in files:
        if v not in index:
            visit(v)
    print(f"{len(files)} files, {sum(len(v) for v in edges.values())} edges, {len(comps)} circles")
    for comp in sorted(comps, key=lambda c: rel(c[0])):
        members = set(comp)
        print("circle: " + " ".join(rel(f) for f in comp))
        for a in comp:
            for b in sorted(edges.get(a, ())):
                if b in members:
                    print(f"    {rel(a)} -> {rel(b)}")
    return 1 if comps else 0


if __name__ == "__main__":
    sys.exit(main())
