#!/usr/bin/env python3
"""Call graph between the firmware core's modules, from their object files.

Each object file is one module (core/seq.c -> seq.o -> module "seq"). `nm` lists
the symbols an object defines and the ones it needs (undefined); an undefined
symbol defined by another core object is a call (or data use) from the first
module into the second. The check fails (exit 1) when

  - the module graph has a cycle (two modules calling each other, or a loop
    through several): every module must sit below the ones that call it;
  - a module defines a global symbol that does not start with its own name and
    an underscore (seq.o defines seq_*, fw_assert.o defines fw_assert_*), so a
    name says where it lives;
  - a module's header (--headers DIR: DIR/seq.h for seq.o) declares a function
    of another module: each header declares only its own module's functions.

Symbols no core object defines (hal_*, memcpy, ...) are the HAL and the C
library: not part of the graph. Standard library only.

Usage:
  check_fw_calls.py [--nm NM] [--headers DIR] OBJ.o...
                                         check the core objects, print the graph
  check_fw_calls.py --self-test          check the checker on made-up nm output
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

DEFINED = set("TDBRCVWGS")  # nm letters of symbols an object provides
UNDEFINED = set("Uw")  # nm letters of symbols it needs (w: weak, unresolved)


def parse_nm(text: str) -> tuple[set[str], set[str]]:
    """Return (defined global symbols, undefined symbols) from `nm` output."""
    defined: set[str] = set()
    needed: set[str] = set()
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 3:
            _, kind, name = parts
        elif len(parts) == 2:
            kind, name = parts
        else:
            continue
        if kind in UNDEFINED:
            needed.add(name)
        elif kind in DEFINED:  # upper case only: lower case is file-local (static)
            defined.add(name)
    return defined, needed


def build_graph(symbols: dict[str, tuple[set[str], set[str]]]) -> dict[str, dict[str, list[str]]]:
    """Module -> {module it needs: [symbols]}, from {module: (defined, needed)}."""
    owner: dict[str, str] = {}
    for module, (defined, _) in symbols.items():
        for name in defined:
            owner.setdefault(name, module)
    graph: dict[str, dict[str, list[str]]] = {m: {} for m in symbols}
    for module, (_, needed) in symbols.items():
        for name in sorted(needed):
            target = owner.get(name)
            if target is not None and target != module:
                graph[module].setdefault(target, []).append(name)
    return graph


def cycles(graph: dict[str, dict[str, list[str]]]) -> list[list[str]]:
    """Every elementary cycle, each once, starting at its smallest module name."""
    nodes = sorted(graph)
    found: list[list[str]] = []

    def walk(start: str, node: str, path: list[str]) -> None:
        for nxt in sorted(graph[node]):
            if nxt == start:
                found.append(path[:])
            elif nxt > start and nxt not in path:
                path.append(nxt)
                walk(start, nxt, path)
                path.pop()

    for start in nodes:
        walk(start, start, [start])
    return found


def tangles(graph: dict[str, dict[str, list[str]]]) -> list[list[str]]:
    """Groups of two or more modules that all reach each other (strong components)."""
    reach = {m: set(graph[m]) for m in graph}
    changed = True
    while changed:  # transitive closure: the graph has a dozen nodes
        changed = False
        for m in reach:
            more = set().union(*(reach[n] for n in reach[m])) - reach[m]
            if more:
                reach[m] |= more
                changed = True
    groups = {tuple(sorted({m} | {n for n in reach[m] if m in reach[n]})) for m in graph}
    return sorted(list(g) for g in groups if len(g) > 1)


def misnamed(symbols: dict[str, tuple[set[str], set[str]]]) -> list[tuple[str, str]]:
    """(module, symbol) for global symbols not named after their module.

    A symbol of the longest matching module name belongs to that module only:
    fw_assert_failed must live in fw_assert.o, not in fw.o."""
    modules = sorted(symbols, key=len, reverse=True)
    bad = []
    for module, (defined, _) in sorted(symbols.items()):
        for name in sorted(defined):
            home = next((m for m in modules if name.startswith(m + "_")), None)
            if home != module:
                bad.append((module, name))
    return bad


# A function declared at the top level of a header: `type name(` at column 0.
PROTOTYPE = re.compile(r"^(?!typedef|static|#|/|\s)[A-Za-z_][\w \t\*]*?\b(\w+)\s*\(", re.M)


def foreign_declarations(module: str, header_text: str) -> list[str]:
    """Functions a module's header declares that are not named module_*."""
    return [n for n in PROTOTYPE.findall(header_text) if not n.startswith(module + "_")]


def report(symbols: dict[str, tuple[set[str], set[str]]], headers: Path | None = None) -> int:
    graph = build_graph(symbols)
    print(f"modules ({len(graph)}): {' '.join(sorted(graph))}")
    for module in sorted(graph):
        calls = ", ".join(f"{t} ({len(s)})" for t, s in sorted(graph[module].items()))
        print(f"  {module} -> {calls or '-'}")
    loops = cycles(graph)
    print(f"call-graph cycles: {len(loops)}")
    for loop in loops:
        steps = []
        for a, b in zip(loop, loop[1:] + loop[:1]):
            steps.append(f"{a} -[{' '.join(graph[a][b][:3])}{' ...' if len(graph[a][b]) > 3 else ''}]-> ")
        print("  " + "".join(steps) + loop[0])
    for group in tangles(graph):
        print(f"  modules tangled in those cycles: {' '.join(group)}")
    pairs = sorted({tuple(sorted((a, b))) for a in graph for b in graph[a] if a in graph[b]})
    print(f"module pairs calling each other: {len(pairs)}"
          + "".join(f" {a}<->{b}" for a, b in pairs))
    bad = misnamed(symbols)
    print(f"symbols not named after their module: {len(bad)}")
    for module, name in bad:
        print(f"  {module}.o defines {name}")
    foreign = []
    if headers is not None:
        for module in sorted(symbols):
            h = headers / f"{module}.h"
            if h.is_file():
                foreign += [(h.name, n) for n in foreign_declarations(module, h.read_text())]
        print(f"headers declaring another module's functions: {len(foreign)}")
        for name, fn in foreign:
            print(f"  {name} declares {fn}")
    if loops or bad or foreign:
        print(
            "FAIL: a core module may only call modules below it (no cycles), and every "
            "global symbol starts with its module's name and is declared in its module's "
            "header only; see firmware/README.md, "
            "'Firmware core'.",
            file=sys.stderr,
        )
        return 1
    return 0


def self_test() -> int:
    """The checker on made-up nm output: it must find what it is for."""
    nm = {
        "a": "0000 T a_run\n         U b_get\n         U memcpy\n",
        "b": "0000 T b_get\n0004 t helper\n         U c_put\n",
        "c": "0000 T c_put\n         U a_run\n0008 B c_count\n",
        "d": "0000 T d_init\n0004 T a_stray\n         U c_put\n",
    }
    symbols = {m: parse_nm(t) for m, t in nm.items()}
    graph = build_graph(symbols)
    assert graph["a"] == {"b": ["b_get"]}, graph
    assert "helper" not in symbols["b"][0] and "c_count" in symbols["c"][0]
    assert cycles(graph) == [["a", "b", "c"]], cycles(graph)
    assert tangles(graph) == [["a", "b", "c"]], tangles(graph)
    assert misnamed(symbols) == [("d", "a_stray")], misnamed(symbols)
    two = {"x": parse_nm("T x_f\nU y_g\n"), "y": parse_nm("T y_g\nU x_f\n")}
    assert cycles(build_graph(two)) == [["x", "y"]]
    fine = {"x": parse_nm("T x_f\nU y_g\n"), "y": parse_nm("T y_g\nU hal_time_us\n")}
    assert cycles(build_graph(fine)) == [] and misnamed(fine) == []
    pre = {"fw": parse_nm("T fw_assert_failed\n"), "fw_assert": parse_nm("T fw_assert_x\n")}
    assert misnamed(pre) == [("fw", "fw_assert_failed")]
    header = "typedef struct {\n    void (*hook)(int);\n} seq_t;\nvoid seq_init(void);\n" \
             "uint16_t led_on(int ch,\n               uint16_t mA);\nstatic inline int x(void);\n"
    assert foreign_declarations("seq", header) == ["led_on"], foreign_declarations("seq", header)
    print("check_fw_calls self-test: ok")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("objects", nargs="*", type=Path, help="core object files, one per module")
    ap.add_argument("--nm", default="nm", help="the nm program (default: nm)")
    ap.add_argument("--headers", type=Path, help="folder of the modules' headers (NAME.h)")
    ap.add_argument("--self-test", action="store_true", help="test the checker itself")
    args = ap.parse_args(argv)
    if args.self_test:
        return self_test()
    if not args.objects:
        ap.error("give the core object files (one per module), or --self-test")
    symbols = {}
    for obj in args.objects:
        if not obj.is_file():
            ap.error(f"{obj}: no such object file; build the core objects first")
        out = subprocess.run([args.nm, str(obj)], capture_output=True, text=True)
        if out.returncode != 0:
            ap.error(f"{args.nm} {obj} failed: {out.stderr.strip()}")
        symbols[obj.stem] = parse_nm(out.stdout)
    return report(symbols, args.headers)


if __name__ == "__main__":
    sys.exit(main())
