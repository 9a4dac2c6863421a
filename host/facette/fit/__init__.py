"""Identification of BRDF parameters on reflectance samples (thesis §4.2.2).

``fit_brdf(s, o, values, model="li", method="least_squares"|"genetic", ...) -> FitResult``;
``FitResult.to_json()`` is the content of brdf.json.
"""
from ._cells import (FITS_RELATIVE_RMS, VERDICT_MODELS, cell_spread_directions, fit_cells_verdict,
                     fit_hemisphere_cells, incidence_spread, preferred_model)
from ._fit import METHODS, WEIGHTINGS, fit_brdf, fit_genetic, fit_least_squares, prepare_samples
from ._models import BOUNDS, FitModel
from ._result import FitResult
from ._normals_li import RefineResult, refine_normals_li
from ._li_model import LI_FIT_BOUNDS, LI_VOLUME_MODEL, fit_li_per_pixel_kd, is_metal, li_fit_cost
from ._ps_li import ps_li_alternating
from ._ps_li_bands import li_model
from ._light_gains import estimate_light_gains, light_gains_over_bands
from ._ps_li_ir import glossy_lobes_text, ps_li_without_interreflections
from ._ps_li_start import start_model_of

__all__ = ["fit_cells_verdict", "incidence_spread", "preferred_model", "FITS_RELATIVE_RMS", "VERDICT_MODELS", "fit_brdf", "fit_genetic", "fit_least_squares", "prepare_samples", "fit_hemisphere_cells",
           "cell_spread_directions", "FitResult", "FitModel",
           "BOUNDS", "METHODS", "WEIGHTINGS",
           "ps_li_alternating", "li_model", "estimate_light_gains", "light_gains_over_bands", "fit_li_per_pixel_kd", "li_fit_cost", "is_metal", "LI_FIT_BOUNDS", "LI_VOLUME_MODEL",
           "refine_normals_li", "RefineResult", "ps_li_without_interreflections",
           "glossy_lobes_text", "start_model_of"]
