"""Benchmarks run by `facette bench NAME` / `make bench`: one module per study,
each with ``main(argv) -> int``, printing error and run time side by side."""
