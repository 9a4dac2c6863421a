"""The kinds of expected failure, shared by every layer (this module imports nothing of facette).

Each kind carries the exit code the `facette` command ends with (README, "Exit codes"):

    0  done
    1  StoppedError        a scan stopped or the device refused / faulted (run again to resume)
    2  BadInputError       an argument, a file or a folder is wrong (nothing was started)
    3  InsufficientData    the data cannot carry the result asked for (change exposure, current, mask)
    70 a bug in facette    (a traceback, and a line asking to report it)
    130 interrupted        (Ctrl-C; what was captured is kept)

A message says what was wrong (the file, the line, the register, the light); `hint`, when
given, says what to do. Layers raise these (or a subclass); the command line prints
``facette <command>: <message>`` and the hint, and exits with `exit_code`.
"""
from __future__ import annotations

__all__ = ["FacetteError", "BadInputError", "StoppedError", "InsufficientData", "NotAReflectance", "EXIT_OK",
           "EXIT_STOPPED", "EXIT_BAD_INPUT", "EXIT_NO_RESULT", "EXIT_BUG", "EXIT_INTERRUPTED"]

EXIT_OK = 0
EXIT_STOPPED = 1
EXIT_BAD_INPUT = 2
EXIT_NO_RESULT = 3
EXIT_BUG = 70          # EX_SOFTWARE of sysexits.h
EXIT_INTERRUPTED = 130


class FacetteError(Exception):
    """An expected failure: `str(exc)` says what was wrong, `hint` what to do (or None)."""

    exit_code = EXIT_STOPPED

    def __init__(self, message, hint=None, exit_code=None):
        super().__init__(message)
        self.message = str(message)
        self.hint = hint
        if exit_code is not None:
            self.exit_code = int(exit_code)

    def __str__(self):
        return f"{self.message}; {self.hint}" if self.hint else self.message

    def user_lines(self):
        """The one or two lines the command line prints: what was wrong, what to do."""
        return [self.message] + ([self.hint] if self.hint else [])


class BadInputError(FacetteError, ValueError):
    """An argument, file or folder that cannot be used; nothing was started or changed."""

    exit_code = EXIT_BAD_INPUT


class StoppedError(FacetteError, RuntimeError):
    """A scan stopped, or the device refused a request or latched a fault."""

    exit_code = EXIT_STOPPED


class InsufficientData(FacetteError, ValueError):
    """The data cannot carry the result asked for (too dark, saturated, too few samples)."""

    exit_code = EXIT_NO_RESULT


class NotAReflectance(InsufficientData):
    """A step that needs the albedo as a reflectance (the inter-reflection removal) got one above 1:
    relative light intensities, or a metal's Lambertian albedo."""
