"""facette.scan: acquisition into a resumable scan directory (DESIGN §7, contract 3)."""
from facette.scan.acquire import (THESIS_BRACKET_US, ScanAborted, ScanError, ScanPlan, default_plan,
                                  run_scan)
from facette.scan.directory import ScanDirectory, ScanDirectoryError, frame_name, sha256_file

__all__ = ["run_scan", "ScanPlan", "default_plan", "ScanError", "ScanAborted", "ScanDirectory",
           "ScanDirectoryError", "frame_name", "sha256_file", "THESIS_BRACKET_US"]
