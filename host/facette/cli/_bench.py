"""`facette bench NAME`: benchmarks that print error and run time side by side.

Each benchmark is a module `facette.bench.<name>` with ``main(argv) -> int``.
"""
import argparse
import functools
import importlib
import pkgutil

import facette.bench


def available():
    return sorted(m.name for m in pkgutil.iter_modules(facette.bench.__path__)
                  if not m.name.startswith("_"))


def register(sub):
    p = sub.add_parser("bench", help="benchmarks: error and run time side by side")
    p.add_argument("name", help=f"one of {', '.join(available()) or '(none yet)'}, or 'all'")
    p.add_argument("rest", nargs=argparse.REMAINDER, help="arguments passed to the benchmark")
    return p


def run(args):
    names = available() if args.name == "all" else [args.name]
    unknown = [n for n in names if n not in available()]
    if unknown:
        raise SystemExit(f"unknown benchmark {unknown[0]!r}; choose from {', '.join(available())}")
    from facette.bench._page import run_teed, write_page

    status, outputs = 0, {}
    for name in names:
        print(f"== facette bench {name}", flush=True)
        outputs[name] = run_teed(functools.partial(importlib.import_module(f"facette.bench.{name}").main, args.rest))
        status |= outputs[name][0]
    if args.name == "all" and not args.rest:          # a whole run writes the benchmarks page
        print(f"wrote {write_page(outputs)}")
    return status
