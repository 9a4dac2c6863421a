"""The processing chain: `process(scan_or_dir, outputs=[...], options=ProcessOptions(...))` runs only
the stages the requested outputs need and writes the files of docs/outputs.md (normal.exr, albedo.exr,
height.exr, mask.png, mesh.ply, samples.npz, brdf.json, relight.ptm, relight.rti, model.glb,
report.html); `batch(scans, out)` runs it over a collection on Dask; `ps_tiled` runs photometric
stereo of a DiLiGenT-style folder over row bands in bounded memory (per-pixel methods), its band
height from a memory budget (`rows_per_tile`)."""
from facette.methods import PROCESS_DEFAULT
from ._channels import CHANNELS, CHANNELS_DEFAULT
from facette.capture import PSInput, auto_masks, load_input, margin_of
from ._options import GAINS_AUTO, IR_AUTO
from ._process import ALL_OUTPUTS, OUTPUTS, STAGES_FOR, ProcessOptions, ProcessResult, preload, process, stages_needed
from ._batch import batch, process_scan
from ._arriving import ArrivingLights
from ._tiles import WHOLE_IMAGE_METHODS, TILED_METHODS, BANDED_METHODS, parse_memory, rows_per_tile, ps_tiled

__all__ = ["CHANNELS", "CHANNELS_DEFAULT", "GAINS_AUTO", "IR_AUTO", "PSInput", "auto_masks", "load_input", "margin_of", "ALL_OUTPUTS", "OUTPUTS", "PROCESS_DEFAULT", "STAGES_FOR", "ProcessOptions", "ProcessResult", "preload", "process",
           "stages_needed", "batch", "process_scan", "WHOLE_IMAGE_METHODS", "TILED_METHODS", "BANDED_METHODS", "parse_memory",
           "rows_per_tile", "ps_tiled", "ArrivingLights"]
