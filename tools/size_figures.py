#!/usr/bin/env python3
"""Size figures of the host package: files over 500 lines, functions over 100 lines, the
parameters of `process` and `run_scan`, imports inside functions (of any module).

    python3 tools/size_figures.py [host/facette]
"""
import ast
import sys
from pathlib import Path


def _params(fn):
    a = fn.args
    return len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)


def _inner_imports(tree):
    """Import statements inside a function (at any depth), each counted once."""
    def walk(node, in_fn):
        here = in_fn or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        own = int(in_fn and isinstance(node, (ast.Import, ast.ImportFrom)))
        return own + sum(walk(child, here) for child in ast.iter_child_nodes(node))
    return walk(tree, False)


def main(argv=None):
    root = Path((argv or sys.argv[1:] or ["host/facette"])[0])
    long_files, long_fns, params, inner = [], [], {}, 0
    for path in sorted(root.rglob("*.py")):
        text = path.read_text()
        n = len(text.splitlines())
        if n > 500:
            long_files.append((n, str(path)))
        tree = ast.parse(text)
        inner += _inner_imports(tree)
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                size = node.end_lineno - node.lineno + 1
                if size > 100:
                    long_fns.append((size, f"{path}:{node.lineno} {node.name}"))
                if node.name in ("process", "run_scan") and node.col_offset == 0:
                    params[f"{path.relative_to(root)} {node.name}"] = _params(node)
    print(f"files over 500 lines: {len(long_files)}")
    for n, p in sorted(long_files, reverse=True):
        print(f"  {n:5d} {p}")
    print(f"functions over 100 lines: {len(long_fns)}")
    for n, p in sorted(long_fns, reverse=True):
        print(f"  {n:5d} {p}")
    for k, v in params.items():
        print(f"parameters of {k}: {v}")
    print(f"import statements inside functions: {inner}")


if __name__ == "__main__":
    main()
