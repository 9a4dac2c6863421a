"""Every photometric-stereo method, in one table, and the one dispatcher by name.

    photometric_stereo(images, light_dirs, method="rank_trimmed", options=None, **more) -> PSResult

`PS_METHODS` is the literal below: a new method is one line there (its function, its aliases),
and nothing adds to the table later (`Registry.fixed`: `PS_METHODS.add` raises). The methods:

    woodham1980 (least_squares)         recon: least squares over every light (Woodham 1980)
    hierarchical_tautzia2016 (hierarchical)  recon: the thesis's shadow and highlight elimination
    rpca_wu2010                         recon: low-rank recovery (Wu et al. 2010)
    rank_trimmed                        recon: per-pixel trimmed least squares (the default)
    bipolynomial_shi2014 (st14)         recon: bi-polynomial reflectance (Shi et al. 2014)
    bivariate_ikehata2014 (ia14)        recon: constrained bivariate regression (Ikehata, Aizawa 2014)
    consensus_higo2010 (hm10)           recon: consensus of order and visibility constraints (Higo et al. 2010)
    li_alternating (brdf_li)            fit: normals and the LI model in alternation

**Options.** A method's options are the keyword parameters of its function, after
`images, light_dirs` (its signature is the declaration, as colour's `filter_kwargs` reads it):
`METHOD_OPTIONS[name]`. A caller passes one bag of options (`options`, a mapping, and/or
keywords) whatever the method; the dispatcher hands the method the ones it takes
(`options_for`) and raises ValueError for a name that no method takes. So a caller never
branches on a method's name: `process` passes its thresholds (t_ombre, t_spec, t_source,
t_residual) and its `ps_options` to every method, and each keeps its own.

**A method that starts from another.** li_alternating's `init` names the method of this table
that gives its starting normals (default rank_trimmed): the name is looked up here (the layer
below cannot see the table), and unless `init_options` is given, that method takes its options
from the same bag: those it declares, except a name li_alternating declares too, which is
li_alternating's (`rounds`: alternation rounds, not rank_trimmed's trimming passes), unless it
means the same to both (`SAME_MEANING`: `t_residual`, the least-squares residual under which a
pixel is Lambertian). With the hierarchy as start, `process`'s thresholds reach it.

Layer: above fit and calib (li_alternating lives in facette.fit, where it can call the BRDF
fit), below sim (docs/ARCHITECTURE.md). recon and fit never dispatch by name: when they need a
photometric-stereo solve they call its function.
"""
import inspect
from types import MappingProxyType

from facette._registry import Registry
from facette.fit import ps_li_alternating
from facette.recon import (ps_bipolynomial_shi2014, ps_bivariate_ikehata2014, ps_consensus_higo2010,
                           ps_hierarchical_tautzia2016, ps_rank_trimmed, ps_rpca_wu2010, ps_woodham1980)

__all__ = ["PS_METHODS", "PS_DEFAULT", "PROCESS_DEFAULT", "METHOD_OPTIONS", "ALL_OPTIONS", "SAME_MEANING", "options_for",
           "photometric_stereo"]

PS_METHODS = Registry.fixed("photometric-stereo method", {
    "woodham1980": (ps_woodham1980, ("least_squares",)),
    "hierarchical_tautzia2016": (ps_hierarchical_tautzia2016, ("hierarchical",)),
    "rpca_wu2010": (ps_rpca_wu2010, ()),
    "rank_trimmed": (ps_rank_trimmed, ()),
    "bipolynomial_shi2014": (ps_bipolynomial_shi2014, ("st14",)),
    "bivariate_ikehata2014": (ps_bivariate_ikehata2014, ("ia14",)),
    "consensus_higo2010": (ps_consensus_higo2010, ("hm10",)),
    "li_alternating": (ps_li_alternating, ("brdf_li",)),
})

# The robust Lambertian solve: the default of `photometric_stereo`, li_alternating's start, and
# the fast choice of `facette process --method`: on real photographs (DiLiGenT, 96 lights)
# rank_trimmed gives 8.6 deg mean against 12.1 for the hierarchy and 12.6 for least squares.
PS_DEFAULT = "rank_trimmed"
# What `facette process` and the one-button scan use unless told otherwise: the BRDF-aware solve,
# which itself decides per material whether the data show a lobe (and which diffuse part) and keeps
# the robust Lambertian normals where they do not (facette.fit._ps_li, round 1). Measured before the
# switch, against rank_trimmed: the simulated rig's scan (Cook-Torrance, 12 lights) normals 0.38 deg
# against 0.70 and heights 0.046 mm against 0.059 (hil_tests/test_scan_heights.py); Mitsuba paints
# 0.08-0.11x least squares against 0.1-0.5x, plaster equal; DiLiGenT crops through `process`,
# 96 lights, 7.98 deg against 9.90, 12 lights 9.77 against 11.54, no object worse than least squares.
# It costs more time (see the issue 24 note); `--method rank_trimmed` is the fast choice.
PROCESS_DEFAULT = "li_alternating"

_INPUTS = ("images", "light_dirs")      # every method's two positional arguments


def _keyword_options(function):
    """The names of `function`'s parameters after images, light_dirs (its options)."""
    params = list(inspect.signature(function).parameters.values())
    if [p.name for p in params[:2]] != list(_INPUTS):
        raise TypeError(f"{function.__name__} must take ({', '.join(_INPUTS)}, ...) first")
    return frozenset(p.name for p in params[2:] if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY))


METHOD_OPTIONS = MappingProxyType({name: _keyword_options(PS_METHODS[name]) for name in PS_METHODS})
ALL_OPTIONS = frozenset().union(*METHOD_OPTIONS.values())
SAME_MEANING = frozenset({"t_residual"})


def _method_name(function):
    """The table's name of `function`, or None when it is not in the table."""
    return next((name for name in PS_METHODS if PS_METHODS[name] is function), None)


def options_for(method, options=None, **more):
    """The keyword arguments `method`'s function takes, from one bag of options.

    method : a name of PS_METHODS (any case, aliases allowed).
    options : mapping of option name -> value (may be None); more : further options (they win).
    Returns a dict; an `init` given by name is the table's function, and `init_options` is filled
    from the bag as the module doc says. Raises ValueError for an unknown method or for an
    option that no method takes.
    """
    bag = {**(options or {}), **more}
    unknown = sorted(set(bag) - ALL_OPTIONS)
    if unknown:
        raise ValueError(f"unknown photometric-stereo option(s) {', '.join(unknown)}; the methods "
                         f"({PS_METHODS.describe()}) take {', '.join(sorted(ALL_OPTIONS))}")
    name = PS_METHODS.canonical(method)
    own = METHOD_OPTIONS[name]
    kwargs = {k: v for k, v in bag.items() if k in own}
    if "init" in own:
        start = kwargs.get("init", inspect.signature(PS_METHODS[name]).parameters["init"].default)
        start_name = PS_METHODS.canonical(start) if isinstance(start, str) else _method_name(start)
        if isinstance(start, str):
            kwargs["init"] = PS_METHODS[start_name]
        if "init_options" not in kwargs and start_name is not None:
            start_own = METHOD_OPTIONS[start_name]
            passed = {k: v for k, v in bag.items()
                      if k in start_own and (k not in own or k in SAME_MEANING)}
            kwargs["init_options"] = passed or None
    return kwargs


def photometric_stereo(images, light_dirs, method=PS_DEFAULT, options=None, **more):
    """Photometric stereo by name: `method` from PS_METHODS (default PS_DEFAULT, "rank_trimmed").

    images : (m, H, W) or (m, H, W, C) float, linear, divided by each light's intensity, m >= 4.
    light_dirs : (m, 3) unit vectors towards the lights, or (H, W, m, 3) per pixel.
    options, **more : one bag of options for whichever method (mask, channel, saturation, the
        method's own); the method gets those it takes (`options_for`).
    Returns the method's `PSResult`.
    """
    return PS_METHODS[method](images, light_dirs, **options_for(method, options, **more))
