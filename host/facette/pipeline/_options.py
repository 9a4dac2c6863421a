"""`ProcessOptions`: every choice `process` makes, but the source, the outputs and the folder.

One definition: each field carries its default, its line of documentation, whether
process.json records it and whether the report lists it; the checks run once, when the object
is made; `facette process` takes its defaults from here.
"""
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path

import numpy as np

from facette.errors import BadInputError
from facette.methods import PROCESS_DEFAULT, options_for
from facette.pipeline._channels import CHANNELS, CHANNELS_DEFAULT
from facette.pipeline._tiles import parse_memory
from facette.recon import HSH_ORDERS, INTEGRATION_DEFAULT, INTEGRATION_METHODS, RTI_ENCODINGS
from facette.recon._ps import T_OMBRE, T_RESIDUAL, T_SOURCE, T_SPEC
from facette.reflect import THETA0_DEG

__all__ = ["ProcessOptions", "GAINS_AUTO", "IR_AUTO", "SHADOWS_AUTO", "SHADOWS_CHOICES"]

GAINS_AUTO = "auto"  # light_gains: for folders solved with the default (`process`)
IR_AUTO = "auto"    # interreflections: removed where the input allows it (`process`)
SHADOWS_AUTO = "auto"   # shadows: cast shadows found where the input shows them (pipeline._shadows)
SHADOWS_CHOICES = (SHADOWS_AUTO, "on", "off")


def _option(default, doc, record=True, report=False, factory=None):
    """A field of ProcessOptions: `record` in process.json, `report` in ProcessResult.options
    (the report's options table); `doc` is its line of the class doc."""
    meta = {"doc": doc, "record": record, "report": report}
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class ProcessOptions:
    """How `process` runs: every choice but the source, the outputs and the results folder.

    Each field's meaning and default are listed below (made from the fields' own lines). The
    fields are checked once, when the object is made (a bad value raises BadInputError or
    ValueError before any file is read); process.json records the fields marked `record`
    (`recorded()`), the report lists those marked `report` (`reported()`).
    `dataclasses.replace(options, method="woodham1980")` gives a variant (checked again).
    """
    method: str = _option(PROCESS_DEFAULT, "photometric stereo: a name of facette.methods.PS_METHODS; default "
                          "PROCESS_DEFAULT (li_alternating, BRDF-aware where the data show a lobe), or e.g. rank_trimmed (robust Lambertian, fast); li_alternating: "
                          "facette.fit.ps_li_alternating, from rank_trimmed's robust normals; albedo.exr is then "
                          "the LI K_d, and brdf.json gains materials and levels; 10-50x slower), "
                          "hierarchical_tautzia2016 (the thesis), woodham1980", report=True)
    integration: str = _option(INTEGRATION_DEFAULT, "a name of recon.INTEGRATION_METHODS: poisson_flat_margin "
                               "(default; needs a flat margin around the object: with a dark background the "
                               "table's lean is taken from it and out of its slopes only), frankot_chellappa1988 "
                               "(the thesis's, needs it too), simchony1990 or least_squares (on the mask only)",
                               report=True)
    channels: str = _option(CHANNELS_DEFAULT, "the colour channels the normals are solved on (pipeline._channels): "
                            "mean (default: of R, G, B; chosen on renders, pipeline._channels.CHANNELS_DEFAULT), "
                            "weighted (R, G, B weighted by mean/variance, one weight per channel, the variance "
                            "estimated from the images) or green (the thesis's); "
                            "the albedo stays per channel; with --memory: mean as whole, weighted falls back to "
                            "green", report=True)
    t_ombre: float = _option(T_OMBRE, "shadow angle threshold, rad (ps_hierarchical_tautzia2016)", report=True)
    t_spec: float = _option(T_SPEC, "specular variance threshold (ps_hierarchical_tautzia2016)", report=True)
    t_source: float = _option(T_SOURCE, "max |entry| of a triplet's inverse (ps_hierarchical_tautzia2016)",
                              report=True)
    t_residual: float = _option(T_RESIDUAL, "least-squares residual under which a pixel is Lambertian "
                                "(ps_hierarchical_tautzia2016, ps_li_alternating)", report=True)
    theta0_deg: float = _option(THETA0_DEG, "hemisphere-sensor cell size, deg", report=True)
    rti_encoding: str = _option("auto", "what relight.ptm and relight.rti hold: auto, the photographs as they "
                                "are (their scale and encoding: sRGB for 8-bit files, linear for 16-bit ones; an "
                                "HDR scan sRGB at an exposure that clips <= 0.1 % of the object, "
                                "pipeline._rti_exposure); srgb or linear: that encoding; said in relight.rti's header",
                                report=True)
    mask: object = _option(None, "(H, W) bool or a PNG path (recorded when a path)")
    pixel_pitch_mm: float = _option(None, "object-side pixel size, mm, > 0 (None: the scan's)")
    near_light: bool = _option(True, "use the lights' positions (per-pixel directions, 1/r^2) when the scan has them")
    mesh_step: int = _option(None, "pixel step of the mesh, >= 1 (None: so that it has at most ~1e6 vertices)")
    ascii_ply: bool = _option(False, "write mesh.ply as ASCII", record=False)
    saturation: float = _option(None, "image values >= this are treated as missing")
    fit_options: dict = _option(None, "keyword arguments of facette.fit.fit_hemisphere_cells (model: 'auto', "
                                "as none, or one model's name; method, volume, ...)", factory=dict)
    ps_options: dict = _option(None, "options of the photometric-stereo method, beside the thresholds above "
                               "(li_alternating: init, rounds, materials, ...): one bag, each method takes "
                               "its own (facette.methods.options_for)", factory=dict)
    hsh_order: int = _option(3, "order of the hemispherical harmonics of relight.rti (2: 4 terms, 3: 9 terms)")
    ptm_format: str = _option("auto", "relight.ptm's format: lrgb (a luminance polynomial times a colour, 9 bytes "
                              "a pixel), rgb (a polynomial per channel, 18 bytes) or auto: the one with the smaller "
                              "leave-one-light-out error on the object (pipeline._rti_bands)", report=True)
    allow_incomplete: bool = _option(False, "process a scan that is not complete (every output then says so)",
                                     record=False)
    overwrite: bool = _option(False, "replace an earlier run's results in out_dir made with other options or "
                              "inputs (without it such a folder is refused: one folder, one run)", record=False)
    interreflections: object = _option(IR_AUTO, "take the light a concave surface gathers from itself out of the "
                                       "images before photometric stereo (see `process`): True, False, or 'auto' "
                                       "(default): on a reflectance-calibrated scan read whole, off elsewhere "
                                       "(a note says why)", report=True)
    shadows: str = _option(SHADOWS_AUTO, "cast shadows from the surface's own heights (pipeline._shadows): 'auto' "
                           "(default: where the first pass's heights hide lights from enough samples), 'on' or "
                           "'off'; a hidden light is no sample for that pixel", report=True)
    light_gains: object = _option(GAINS_AUTO, "read each light's relative intensity from the photographs and "
                                  "correct the given ones (pipeline._light_gains): True, False, or 'auto' (default): "
                                  "for folders (DiLiGenT, RTI captures) solved with li_alternating under lights where "
                                  "a 1 % error tilts the normals by 0.37-1.48°, not for scans (their intensities "
                                  "are measured on the Spectralon)", report=True)
    capture: dict = _option(None, "options of an RTI capture folder (photographs + .lp, or a mirror sphere in "
                            "view): {encoding: srgb|linear, sphere: Circle or (H, W) mask, reference: (x0, y0, "
                            "x1, y1)}; see capture.rti.read_rti_capture; recorded only when given "
                            "(its values as text, a mask array left out)", record=False)

    memory: str = _option(None, "a memory budget ('2GB', '512MB', '3GiB' or bytes): photometric stereo then runs "
                          "over bands of rows in it (pipeline._tiles.BANDED_METHODS: the per-pixel ones, li_alternating); any capture's "
                          "photographs are read band by band, never whole (the samples, PTM and HSH fits too); recorded "
                          "only when given; None: a budget from the free memory (pipeline._budget), used when the "
                          "capture does not fit whole")

    scheduler: str = _option(None, "with memory: the address of a dask.distributed scheduler (tcp://host:8786) whose "
                             "workers run the bands (they must see the scan's path); None: here, one after the other",
                             record=False)

    @property
    def memory_bytes(self):
        """The memory budget in bytes, or None."""
        return None if self.memory is None else parse_memory(self.memory)

    def __post_init__(self):
        # copies, so that a caller's dict changed later does not change these options
        object.__setattr__(self, "fit_options", dict(self.fit_options or {}))
        object.__setattr__(self, "ps_options", dict(self.ps_options or {}))
        if self.rti_encoding not in ("auto",) + RTI_ENCODINGS:
            raise BadInputError(f"rti_encoding must be one of auto, {', '.join(RTI_ENCODINGS)}, "
                                f"got {self.rti_encoding!r}")
        if self.pixel_pitch_mm is not None and not self.pixel_pitch_mm > 0:
            raise BadInputError(f"pixel_pitch_mm must be > 0 mm, got {self.pixel_pitch_mm}")
        if self.mesh_step is not None and not int(self.mesh_step) >= 1:
            raise BadInputError(f"mesh_step must be >= 1 pixel, got {self.mesh_step}")
        if self.ptm_format not in ("auto", "lrgb", "rgb"):
            raise BadInputError(f"ptm_format must be auto, lrgb or rgb, got {self.ptm_format!r}")
        if self.hsh_order not in HSH_ORDERS:
            raise ValueError(f"hsh_order = {self.hsh_order}: choose one of {HSH_ORDERS}")
        if self.channels not in CHANNELS:
            raise BadInputError(f"channels must be one of {', '.join(CHANNELS)}, got {self.channels!r}")
        if isinstance(self.interreflections, str) and self.interreflections != IR_AUTO \
                or self.interreflections not in (True, False, IR_AUTO):
            raise BadInputError(f"interreflections must be True, False or {IR_AUTO!r}, got {self.interreflections!r}")
        if self.interreflections != IR_AUTO:
            object.__setattr__(self, "interreflections", bool(self.interreflections))
        if self.shadows not in SHADOWS_CHOICES:
            raise BadInputError(f"shadows must be one of {', '.join(SHADOWS_CHOICES)}, got {self.shadows!r}")
        if isinstance(self.light_gains, str) and self.light_gains != GAINS_AUTO \
                or self.light_gains not in (True, False, GAINS_AUTO):
            raise BadInputError(f"light_gains must be True, False or {GAINS_AUTO!r}, got {self.light_gains!r}")
        INTEGRATION_METHODS.canonical(self.integration)        # ValueError naming the valid ones
        options_for(self.method, self.ps_bag())                # an unknown method or option: ValueError
        if self.memory is not None:
            from facette.pipeline._tiled_process import check_memory_options
            parse_memory(self.memory)                           # '2 apples': ValueError
            check_memory_options(self.method, self.interreflections is True)
        elif self.scheduler is not None:
            raise ValueError("--scheduler runs the bands of --memory on a Dask cluster: give --memory too "
                             "(e.g. --memory 2GB), or leave --scheduler out")

    def ps_bag(self, **more):
        """The one bag of photometric-stereo options: the thresholds, then ps_options, then `more`."""
        return {"t_ombre": self.t_ombre, "t_spec": self.t_spec, "t_source": self.t_source,
                "t_residual": self.t_residual, **self.ps_options, **more}

    def recorded(self):
        """{name: value} of the fields process.json records (a mask array is recorded as None)."""
        out = {}
        for f in fields(self):
            if f.metadata["record"]:
                value = getattr(self, f.name)
                if f.name == "mask":
                    value = str(value) if isinstance(value, (str, Path)) else None
                if f.name == "memory" and value is None:
                    continue     # recorded only when given: earlier runs' records stay comparable
                out[f.name] = value
        said = {k: str(v) for k, v in (self.capture or {}).items() if v is not None and not isinstance(v, np.ndarray)}
        if said:                 # recorded only when given: earlier runs' records stay comparable
            out["capture"] = said
        return out

    def reported(self):
        """{name: value} of the fields the report lists (ProcessResult.options)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.metadata["report"]}


ProcessOptions.__doc__ += "\n" + "\n".join(          # the fields' lines, from the fields themselves
    f"    {f.name} : {f.metadata['doc']} "
    f"(default {f.default if f.default_factory is MISSING else f.default_factory()!r})"
    for f in fields(ProcessOptions)) + "\n"
