"""Shape from the HDR images: photometric stereo and integration of the gradient field.

Photometric stereo (thesis §4.2.1): `ps_woodham1980`, `ps_hierarchical_tautzia2016`; robust
methods for real photographs: `ps_rpca_wu2010` (low-rank recovery), `ps_rank_trimmed` (per-pixel
trimmed least squares); published peers for general isotropic BRDFs: `ps_bipolynomial_shi2014`,
`ps_bivariate_ikehata2014`, `ps_consensus_higo2010`; each called directly here, and by name through `facette.methods` (the one
table of photometric-stereo methods, with fit's li_alternating). Integration: `integrate_poisson_flat_margin`
(the default), `integrate_frankot_chellappa1988` (the thesis's), `integrate_simchony1990`, `integrate_least_squares`,
dispatched by `integrate(..., method=)`.
The dark level of each photograph (black level, ambient light: what pixels read with their light
behind them), for the methods that predict 0 there: `dark_offsets`, `dark_level_notes`.
Normals where none was measured (no light above the noise), interpolated from those around them:
`fill_normals`. Inter-reflections of concave matte surfaces taken out of the images before photometric stereo:
`remove_interreflections` (`without_interreflections`: with its first shape). The lights a surface hides
from itself (cast shadows), by a horizon test on its heights: `hidden_lights`.
Relighting functions for RTI (PTM, Malzbender 2001; hemispherical harmonics, Gautron 2004):
`fit_ptm_lrgb`, `fit_hsh`; facette's relighting model (normals, per-pixel reflectance maps, cast
shadows, a residual interpolated over the lights): `fit_relight_model`, saved by `save_relight_model`.
"""
from ._ps import PSResult, ps_woodham1980, ps_hierarchical_tautzia2016, triplet_inverses, near_light_directions
from ._ps_robust import ps_rpca_wu2010, ps_rank_trimmed
from ._ps_peers import ps_bipolynomial_shi2014, ps_bivariate_ikehata2014   # published peers
from ._ps_consensus import ps_consensus_higo2010
from ._uncertainty import normal_uncertainty, uncertainty_summary   # how far each normal may be off
from ._integrate import (normals_to_gradients, integrate_frankot_chellappa1988,
                         integrate_simchony1990, integrate_poisson_flat_margin, integrate_least_squares,
                         integrate, INTEGRATION_DEFAULT, INTEGRATION_METHODS, mesh_from_height, MESH_MAX_SLOPE,
                         flat_margin, MIN_BACKGROUND_PIXELS)
from ._dark import dark_offsets, dark_level_notes
from ._fill import fill_normals, FILL_TOLERANCE
from ._interreflect import (remove_interreflections, without_interreflections, IR_GRID, IR_MAX_FRACTION,
                            IR_PASSES, IR_SKIP_P95)
from ._interreflect_scale import estimate_reflectance_scale, scale_from_images, unidentified_info
from ._shadows import hidden_lights, horizon_excess, heights_in_pixels
from ._relight_model import RelightModel, save_relight_model, load_relight_model, cast_shadow
from ._relight_fit import fit_relight_model, fit_relight_bands
from ._rti import (ptm_basis, hsh_basis, PTMFit, HSHFit, fit_ptm_lrgb, fit_hsh, fit_relight_error,
                   relight_error_parts, relight_ptm, relight_hsh, relight_error, HSH_ORDERS, RELIGHT_ERROR_VALUES,
                   relight_error_step, RTI_ENCODINGS, srgb_encode, srgb_decode, display_ptm, display_hsh)

__all__ = ["PSResult", "normal_uncertainty", "uncertainty_summary", "ps_woodham1980", "ps_hierarchical_tautzia2016", "ps_rpca_wu2010",
           "ps_rank_trimmed", "ps_bipolynomial_shi2014", "ps_bivariate_ikehata2014", "ps_consensus_higo2010",
           "triplet_inverses", "dark_offsets", "dark_level_notes", "fill_normals", "FILL_TOLERANCE",
           "near_light_directions",
           "normals_to_gradients", "integrate_frankot_chellappa1988", "integrate_simchony1990",
           "integrate_poisson_flat_margin", "integrate_least_squares", "integrate", "INTEGRATION_DEFAULT",
           "INTEGRATION_METHODS", "mesh_from_height", "MESH_MAX_SLOPE", "flat_margin", "MIN_BACKGROUND_PIXELS",
           "ptm_basis", "hsh_basis", "PTMFit", "HSHFit", "fit_ptm_lrgb", "fit_hsh", "relight_ptm",
           "relight_hsh", "relight_error", "fit_relight_error", "relight_error_parts", "HSH_ORDERS", "RTI_ENCODINGS",
           "srgb_encode", "srgb_decode", "display_ptm", "display_hsh",
           "RELIGHT_ERROR_VALUES", "relight_error_step", "remove_interreflections", "without_interreflections",
           "IR_GRID", "IR_MAX_FRACTION", "IR_PASSES", "IR_SKIP_P95", "estimate_reflectance_scale",
           "scale_from_images", "unidentified_info", "hidden_lights", "horizon_excess",
           "heights_in_pixels",
           "RelightModel", "fit_relight_model", "fit_relight_bands", "save_relight_model", "load_relight_model", "cast_shadow"]
