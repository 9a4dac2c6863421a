"""BRDF models, the interfaced Lambertian (LI) microfacet model and its building blocks.

Every model is ``f(s, o, **params) -> ndarray`` (1/sr) with s, o (..., 3) unit vectors in
the local frame (normal +z); ``get(name)`` returns one by name ("lambert", "oren_nayar",
"cook_torrance", "li"). Thesis chapter 3; equation numbers in each docstring.
"""
from ._fresnel import fresnel_dielectric, r_e_molenaar1999, r_i_simonot2009
from ._interreflection import (build_interreflection_table, interreflection_integral_vcavity,
                               interreflection_mixed_integral_vcavity, interreflection_vcavity)
from ._microfacet import (DISTRIBUTIONS, MASKINGS, SIGMA_FLAT, distribution_d, gaussian_norm_exact,
                          gaussian_norm_rational_tsb2014, masking_g, microfacet_quadrature,
                          sample_microfacet_normals, smith_g1)
from ._models import (INTERREFLECTION_MIN_SIGMA, MODELS, brdf_li, cook_torrance1982, get, lambert,
                      li_kd_factor, li_specular, li_volume, oren_nayar1994, prepare_directions)
from ._volume import (VOLUME_METHODS, VolumeTable, build_volume_table, volume_integral,
                      volume_integral_approx, volume_integral_monte_carlo, volume_integral_quadrature,
                      volume_integral_table)
from ._albedo import directional_albedo
from ._coupled import coupled_internal_reflectance, coupled_transmittance, diffuse_r_i
from ._shading import kd_from_kappa, kappa_from_kd, li_kappa, li_kd_from_kappa, li_shading_terms

__all__ = [
    "fresnel_dielectric", "r_e_molenaar1999", "r_i_simonot2009",
    "DISTRIBUTIONS", "MASKINGS", "SIGMA_FLAT", "distribution_d", "gaussian_norm_exact", "gaussian_norm_rational_tsb2014",
    "masking_g", "microfacet_quadrature", "sample_microfacet_normals", "smith_g1",
    "INTERREFLECTION_MIN_SIGMA", "MODELS", "brdf_li", "cook_torrance1982", "get", "lambert", "li_kd_factor",
    "li_specular", "li_volume", "oren_nayar1994", "prepare_directions",
    "VOLUME_METHODS", "VolumeTable", "build_volume_table", "volume_integral", "volume_integral_approx",
    "volume_integral_monte_carlo", "volume_integral_quadrature", "volume_integral_table",
    "interreflection_integral_vcavity", "interreflection_mixed_integral_vcavity", "interreflection_vcavity",
    "build_interreflection_table",
    "directional_albedo", "coupled_transmittance", "coupled_internal_reflectance", "diffuse_r_i",
    "li_kappa", "li_kd_from_kappa", "kd_from_kappa", "kappa_from_kd", "li_shading_terms",
]
