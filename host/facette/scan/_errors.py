"""How a scan stops: `ScanError` (the directory holds everything captured so far; the same
scan run again resumes it) and `ScanAborted` (a host call or a second button press)."""
from facette.errors import StoppedError

__all__ = ["ScanError", "ScanAborted"]


class ScanError(StoppedError):
    """The scan stopped; the directory holds everything captured so far."""


class ScanAborted(ScanError):
    """The scan was aborted (host call or second button press)."""
