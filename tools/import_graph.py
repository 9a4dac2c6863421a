#!/usr/bin/env python3
"""Figures of the host package's import graph, read from the source with `ast` (nothing imported).

Prints, per subpackage of `facette`: modules and lines; then the imports between subpackages
(module-level and inside functions, counted apart), the cycles between subpackages (strongly
connected groups of two or more), and the imports that point up the layer order written in
docs/ARCHITECTURE.md (LAYERS below; the import-linter contract in pyproject.toml is the check).

    python3 tools/import_graph.py [--root host/facette]
"""
import argparse
import ast
import sys
from collections import defaultdict
from pathlib import Path

# Lowest first; names in one tuple are one layer (independent siblings). Keep in step with
# docs/ARCHITECTURE.md and [tool.importlinter] in pyproject.toml.
LAYERS = (
    ("_registry", "_data"),
    ("device", "camera", "io"),
    ("brdf",),
    ("hdr", "recon", "reflect"),
    ("fit", "calib"),
    ("methods",),
    ("sim",),
    ("scan",),
    ("capture",),
    ("pipeline", "wizard"),
    ("bench",),
    ("cli",),
)


def module_name(path, root):
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def resolve(node, module, is_package):
    """Absolute module names imported by an Import/ImportFrom node of `module`."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    base = node.module or ""
    if node.level:
        pkg = module.split(".") if is_package else module.split(".")[:-1]
        pkg = pkg[: len(pkg) - (node.level - 1)]
        base = ".".join(pkg + ([base] if base else []))
    # `from facette.x import y` may import the submodule y: count it as x.y when y is a module.
    return [base] + [f"{base}.{alias.name}" for alias in node.names]


def subpackage(name):
    parts = name.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "facette" else None


def scan(root):
    modules = {}
    edges = []  # (from_module, to_module, inside_function)
    for path in sorted(root.rglob("*.py")):
        name = module_name(path, root)
        text = path.read_text()
        modules[name] = len(text.splitlines())
        tree = ast.parse(text)
        inside = set()
        for fn in ast.walk(tree):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for node in ast.walk(fn):
                    inside.add(id(node))
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for target in resolve(node, name, path.name == "__init__.py"):
                    if target.startswith("facette"):
                        edges.append((name, target, id(node) in inside))
    return modules, edges


def sccs(graph):
    """Tarjan's strongly connected components of a dict node -> set(nodes)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
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
            out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1] / "host/facette")
    args = ap.parse_args(argv)
    modules, edges = scan(args.root)
    rank = {name: i for i, layer in enumerate(LAYERS) for name in layer}

    per_pkg = defaultdict(lambda: [0, 0])
    for name, lines in modules.items():
        pkg = subpackage(name) or "facette"
        per_pkg[pkg][0] += 1
        per_pkg[pkg][1] += lines
    print("subpackage   layer  modules  lines")
    for pkg in sorted(per_pkg, key=lambda p: (rank.get(p, -1), p)):
        n, lines = per_pkg[pkg]
        print(f"{pkg:12} {rank.get(pkg, '-')!s:>5}  {n:7}  {lines:5}")

    real = [(a, b, f) for a, b, f in edges if b in modules]
    cross = [(a, b, f) for a, b, f in real
             if subpackage(a) and subpackage(b) and subpackage(a) != subpackage(b)]
    fn_imports = [e for e in real if e[2]]
    graph = defaultdict(set)
    for a, b, _ in cross:
        graph[subpackage(a)].add(subpackage(b))
    cycles = [c for c in sccs(graph) if len(c) > 1]
    pair_cycles = sorted({tuple(sorted((p, q))) for p in graph for q in graph[p] if p in graph.get(q, ())})
    upward = sorted({(a, b) for a, b, _ in cross
                     if rank.get(subpackage(b), -1) > rank.get(subpackage(a), -1)
                     or (rank.get(subpackage(b)) == rank.get(subpackage(a)))})
    print(f"\nmodules: {len(modules)}")
    print(f"imports of facette modules: {len(real)} ({len(fn_imports)} inside functions)")
    print(f"imports between subpackages: {len(cross)} ({sum(f for *_, f in cross)} inside functions)")
    print(f"subpackage pairs importing each other: {len(pair_cycles)} {pair_cycles}")
    print(f"cycles between subpackages (strongly connected groups): {len(cycles)} {cycles}")
    print(f"module imports up or across the layer order: {len(upward)}")
    for a, b in upward:
        print(f"  {a} -> {b}")
    print("\nfunction-level imports of facette modules:")
    for a, b, _ in sorted(set(fn_imports)):
        print(f"  {a} -> {b}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
