"""`facette` command: dispatches to one module per subcommand.

Each subcommand lives in `facette/cli/_<name>.py` and defines
``register(subparsers) -> argparse.ArgumentParser`` and ``run(args) -> int``.
Modules are imported only when their command runs, so a missing optional
dependency of one command never breaks another.

Exit codes (facette.errors): 0 done, 1 a stopped scan or a device fault, 2 bad input
(nothing started), 3 data that cannot give a result, 70 a bug in facette (traceback),
130 interrupted. An expected failure ends in one or two lines: what was wrong, what to do.
"""
import argparse
import importlib
import os
import sys
import traceback

from facette._memory import keep_freed_memory

keep_freed_memory()         # before numpy is imported or a thread starts (facette/_memory.py)

from facette.errors import EXIT_BAD_INPUT, EXIT_BUG, EXIT_INTERRUPTED, EXIT_STOPPED, FacetteError
from facette.io.atomic import DiskFullError, disk_full_error, is_disk_full

REPORT_URL_HINT = ("this is a bug in facette, not in what you did: please report it with the "
                   "command line and the traceback above")

# What Ctrl-C leaves, per command (each is a test's: the command run again does what it says)
INTERRUPTED = {
    "scan": "whatever was captured is kept: the same command resumes the scan",
    "process": "the inputs are untouched and the results folder is marked as interrupted: the same command "
               "redoes it",
    "batch": "the scans are untouched; the scans done are kept: the same command processes the others",
    "calibrate": "the profile being made is not written; the same command starts the wizard again",
}

# name -> (module, one-line help)
COMMANDS = {
    "scan": ("facette.cli._scan", "acquire a scan (simulated rig or a real device)"),
    "process": ("facette.cli._process", "process a scan or a DiLiGenT-style folder"),
    "batch": ("facette.cli._batch", "process many scans on Dask, with one summary table"),
    "calibrate": ("facette.cli._calibrate", "the calibration wizard"),
    "device": ("facette.cli._device", "device info, faults and registers"),
    "sim": ("facette.cli._sim", "start the simulated rig"),
    "bench": ("facette.cli._bench", "benchmarks: error and run time side by side"),
    "relight": ("facette.cli._relight", "render a .ptm, .rti, relight_web folder or relight_model.npz under a light"),
}


class _Parser(argparse.ArgumentParser):
    """argparse, with a bad argument told in two lines (the error, where to read more)
    instead of the whole usage."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: {message}\n  see: {self.prog} --help\n")


def build_parser(command=None):
    parser = _Parser(prog="facette", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
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
        print(f"facette {command}: interrupted; {INTERRUPTED.get(command, 'nothing of yours was changed')}",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    except BaseException as exc:   # noqa: B902 - sorted into expected failures and bugs below
        code, lines = explain(exc, command)
        if code is None:
            raise
        for line in lines:
            print(f"facette {command}: {line}" if line is lines[0] else f"  {line}", file=sys.stderr)
        return code


def _raised_by_facette(exc):
    """True when the innermost frame that raised `exc` is facette's own code: a ValueError
    with a sentence for a person (house rule), not one from deep inside numpy."""
    tb = exc.__traceback__
    last = None
    while tb is not None:
        last = tb
        tb = tb.tb_next
    if last is None:
        return False
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return os.path.abspath(last.tb_frame.f_code.co_filename).startswith(here + os.sep)


def _os_error_lines(exc):
    what = exc.strerror or str(exc)
    name = exc.filename
    if isinstance(exc, (IsADirectoryError, NotADirectoryError, FileExistsError)):
        todo = "choose another path (an output needs a new or empty folder, an input an existing file)"
    elif isinstance(exc, PermissionError):
        todo = "choose a folder you can write to, or fix its permissions"
    elif isinstance(exc, FileNotFoundError):
        todo = "check the path"
    else:
        todo = "check the path, the disk and its free space"
    return [f"{name}: {what}" if name else what, todo]


def explain(exc, command=None):
    """(exit code, lines) for an expected failure; (None, None) for a bug. A full disk during
    `facette scan` is a stopped scan (exit 1: it resumes once space is freed).

    A bug keeps its traceback and gets a line asking to report it (exit 70)."""
    if isinstance(exc, SystemExit):
        if isinstance(exc.code, str):                # a message for the user
            return EXIT_BAD_INPUT, [exc.code]
        return None, None
    if command == "scan" and isinstance(exc, (DiskFullError, OSError)) and is_disk_full(exc):
        full = disk_full_error(getattr(exc, "filename", None) or os.getcwd(), exit_code=EXIT_STOPPED) \
            if isinstance(exc, OSError) else exc
        return EXIT_STOPPED, full.user_lines()
    if isinstance(exc, FacetteError):
        return exc.exit_code, exc.user_lines()
    if isinstance(exc, OSError) and is_disk_full(exc):
        full = disk_full_error(exc.filename or os.getcwd())
        return full.exit_code, full.user_lines()
    if isinstance(exc, OSError) and getattr(exc, "filename", None):
        return EXIT_BAD_INPUT, _os_error_lines(exc)
    if isinstance(exc, (ValueError, FileNotFoundError)) and _raised_by_facette(exc):
        return EXIT_BAD_INPUT, [str(exc)]
    if isinstance(exc, Exception):
        traceback.print_exception(exc, file=sys.stderr)
        return EXIT_BUG, [REPORT_URL_HINT]
    return None, None


if __name__ == "__main__":
    sys.exit(main())
