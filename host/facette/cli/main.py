"""`facette` command: dispatches to one module per subcommand.

Each subcommand lives in `facette/cli/_<name>.py` and defines
``register(subparsers) -> argparse.ArgumentParser`` and ``run(args) -> int``.
Modules are imported only when their command runs, so a missing optional
dependency of one command never breaks another.
"""
import argparse
import importlib
import sys

# name -> (module, one-line help)
COMMANDS = {
    "scan": ("facette.cli._scan", "acquire a scan (simulated rig or a real device)"),
    "process": ("facette.cli._process", "process a scan or a DiLiGenT-style folder"),
    "batch": ("facette.cli._batch", "process many scans on Dask, with one summary table"),
    "calibrate": ("facette.cli._calibrate", "the calibration wizard"),
    "device": ("facette.cli._device", "device info, faults and registers"),
    "sim": ("facette.cli._sim", "start the simulated rig"),
    "bench": ("facette.cli._bench", "benchmarks: error and run time side by side"),
}


def build_parser(command=None):
    parser = argparse.ArgumentParser(prog="facette", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        if name == command:
            importlib.import_module(module).register(sub)  # full options of the one that runs
        else:
            sub.add_parser(name, help=help_text, add_help=False)
    return parser


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    command = argv[0] if argv and argv[0] in COMMANDS else None
    parser = build_parser(command)
    args = parser.parse_args(argv)
    if command is None:
        parser.print_help()
        return 0 if not argv else 2
    module = importlib.import_module(COMMANDS[command][0])
    try:
        return int(module.run(args) or 0)
    except KeyboardInterrupt:
        print("interrupted; whatever was captured is kept (the scan resumes with the same command)",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
