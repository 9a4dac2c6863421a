"""facette.scan: acquisition into a resumable scan directory (its format: docs/scan-format.md),
and the scan directory's HDR merge (`merge_scan`, `load_hdr`: raw/ frames to hdr/light_XX.exr)."""
from facette.scan.acquire import (THESIS_BRACKET_US, ScanAborted, ScanError, ScanOptions, ScanPlan,
                                  default_plan, run_scan)
from facette.scan.directory import (ScanDirectory, ScanDirectoryBusy, ScanDirectoryError, frame_name,
                                    read_scan_manifest, sha256_file)
from facette.scan.manifest import Exposure, Frame, Hdr, HdrLight, Light, Manifest
from facette.scan.rig import TIMING_MODES, Rig, RigFault, SimRig, connect, decode_frame_record
from facette.scan.hdr import (HDR_UNIT, HeldLight, LightMerger, MissingFrameWarning, frame_exposure,
                              load_hdr, merge_scan, stale_lights)

__all__ = ["run_scan", "ScanOptions", "ScanPlan", "default_plan", "ScanError", "ScanAborted",
           "ScanDirectory", "Manifest", "Light", "Exposure", "Frame", "HdrLight", "Hdr", "ScanDirectoryError",
           "ScanDirectoryBusy", "frame_name",
           "sha256_file", "THESIS_BRACKET_US", "read_scan_manifest", "merge_scan", "LightMerger",
           "HeldLight", "load_hdr", "stale_lights", "frame_exposure", "MissingFrameWarning", "HDR_UNIT",
           "Rig", "SimRig", "RigFault", "connect", "decode_frame_record", "TIMING_MODES"]
