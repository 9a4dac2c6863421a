"""The processing chain: `process(scan_or_dir, outputs=[...])` runs only the stages the
requested outputs need and writes the files of DESIGN §7 (normal.exr, albedo.exr,
height.exr, mask.png, mesh.ply, samples.npz, brdf.json, report.html)."""
from ._inputs import PSInput, load_input
from ._process import OUTPUTS, STAGES_FOR, ProcessResult, process, stages_needed

__all__ = ["PSInput", "load_input", "OUTPUTS", "STAGES_FOR", "ProcessResult", "process",
           "stages_needed"]
