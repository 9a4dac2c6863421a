"""facette.scan: acquisition into a resumable scan directory (DESIGN §7, contract 3), and
the scan directory's HDR merge (`merge_scan`, `load_hdr`: raw/ frames to hdr/light_XX.exr)."""
from facette.scan.acquire import (THESIS_BRACKET_US, ScanAborted, ScanError, ScanPlan, default_plan,
                                  run_scan)
from facette.scan.directory import (ScanDirectory, ScanDirectoryBusy, ScanDirectoryError, frame_name,
                                    read_scan_manifest, sha256_file)
from facette.scan.rig import TIMING_MODES, Rig, RigFault, connect, decode_frame_record
from facette.scan.hdr import (HDR_UNIT, LightMerger, MissingFrameWarning, frame_exposure, load_hdr,
                              merge_scan, release_held_lights, stale_lights, take_held_light)

__all__ = ["run_scan", "ScanPlan", "default_plan", "ScanError", "ScanAborted", "ScanDirectory",
           "ScanDirectoryError", "ScanDirectoryBusy", "frame_name", "sha256_file", "THESIS_BRACKET_US",
           "read_scan_manifest", "merge_scan", "LightMerger", "load_hdr", "stale_lights", "frame_exposure",
           "MissingFrameWarning", "HDR_UNIT", "take_held_light", "release_held_lights",
           "Rig", "RigFault", "connect", "decode_frame_record", "TIMING_MODES"]
