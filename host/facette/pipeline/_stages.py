"""What each output of `process` needs: its stages (`STAGES_FOR`, `stages_needed`) and its file
(`FILES`); `OUTPUTS` the default set, `ALL_OUTPUTS` with those asked for by name only."""

__all__ = ["OUTPUTS", "ALL_OUTPUTS", "STAGES_FOR", "FILES", "stages_needed"]

OUTPUTS = ("normals", "albedo", "mask", "height", "mesh", "samples", "brdf", "ptm", "rti", "gltf", "report")
# asked for by name only (not in the default): relight_web/ costs ~0.4 CPU s per megapixel of JPEG
# tiles, relight_model.npz fits every pixel (the report fits the model at _relight_model_stage.MODEL_SIDE only)
ALL_OUTPUTS = OUTPUTS + ("relight-web", "relight")
STAGES_FOR = {
    "normals": ("load", "ps"), "albedo": ("load", "ps"), "mask": ("load", "ps"),
    "height": ("load", "ps", "integrate"), "mesh": ("load", "ps", "integrate", "mesh"),
    "samples": ("load", "ps", "samples"), "brdf": ("load", "ps", "samples", "fit"),
    # the polynomial files need the images and the object's mask, not the normals
    "ptm": ("load", "ptm"), "rti": ("load", "hsh"), "relight-web": ("load", "hsh"),
    "relight": ("load", "ps", "integrate", "relight"), "report": ("load", "ps", "integrate", "relight"),
    # the glTF's material: the relighting model's per-pixel maps (pipeline._gltf_maps); a BRDF fit
    # asked for beside it (brdf) still says whether the object is a metal
    "gltf": ("load", "ps", "integrate", "mesh", "relight")}
FILES = {"normals": "normal.exr", "albedo": "albedo.exr", "mask": "mask.png", "height": "height.exr",
         "mesh": "mesh.ply", "samples": "samples.npz", "brdf": "brdf.json", "ptm": "relight.ptm",
         "rti": "relight.rti", "relight-web": "relight_web", "relight": "relight_model.npz", "gltf": "model.glb",
         "report": "report.html"}

def stages_needed(outputs):
    """Ordered stage names for a list of outputs (unknown names raise ValueError)."""
    bad = [o for o in outputs if o not in STAGES_FOR]
    if bad:
        raise ValueError(f"unknown output(s) {bad}; choose from {', '.join(ALL_OUTPUTS)}")
    order = ("load", "ps", "integrate", "mesh", "samples", "fit", "ptm", "hsh", "relight")
    want = {s for o in outputs for s in STAGES_FOR[o]}
    return [s for s in order if s in want]
