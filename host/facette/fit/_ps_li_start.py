"""li_alternating's round 1 started from an earlier solve's model (`ps_li_alternating(start_model=)`):
the inter-reflection decision (facette.pipeline._interreflections) runs li_alternating on the images
brought to a reflectance's range (and binned, above its DECIDE_SIDE) before the method runs; where it
solved the same pixels, the solves after it (the removal's, the shadow step's, the method's) take its
model choice instead of making their own.

What carries over is the choice of a lobe or none, not the numbers: li's (σ, n_i)
depend on the images' scale (the lobe's height is absolute, the diffuse part scales with the
images: a Mitsuba sphere in paint 0.10 fits n_i 1.30 as rendered, 1.21 at half the values, 1.46 at
twice), and the decision's images are scaled. So a lobe's (σ, n_i) is the warm-up's start
(`_li_model._warm_up`: normals solved against it, (σ, n_i) refitted until they settle) on this
solve's own profile pixels, which skips the grid search of `choose_material_model` (its ~55 solves
of the profile pixels and the check on a draw of the material's pixels). Taken as it was, the
decision's (σ, n_i) on the sphere at half the values: 0.45 -> 0.83 deg.
"""

from ._li_model import LAMBERTIAN_SIGMA, _diffuse_at_fits, _has_interface, _warm_up, diffuse_name, is_metal

__all__ = ["start_model_of", "choice_from_start"]


def start_model_of(ps):
    """(fit, choice) that `ps_li_alternating(start_model=)` takes, from an earlier li_alternating
    result `ps` on the same pixels (the inter-reflection decision's, on images only scaled), or None:
    several materials or no model choice made. The fit is its last (σ, n_i) and diffuse part."""
    mats = ps.info.get("materials") or []
    if len(mats) != 1 or "model_choice" not in mats[0] or mats[0].get("sigma") is None:
        return None
    mat = mats[0]
    choice = dict(mat["model_choice"], made_on="an earlier solve of the same object")
    return {"sigma": float(mat["sigma"]), "n_i": float(mat["n_i"]), "volume_model": mat["volume_model"]}, choice


def choice_from_start(px, fsel, pix, start_model):
    """Round 1's (fit, warm-up refits, choice) from `start_model` (module doc) on the `Pixels` px:
    its profile pixels drawn from the fit pixels `fsel` and its check pixels from the material's `pix`,
    as `Pixels.choose_model` draws them. A dielectric lobe's diffuse part is chosen again, each part
    warmed up from the start's (σ, n_i) and scored on the check pixels (`_li_model._diffuse_at_fits`):
    the parts differ at grazing angles, where the decision's images still held the light the surface
    gathers (Mitsuba craters in paint 0.10, 12 rig lights: "lambert" there, "coupled" on the images
    without it; taken as it was, 2.62 -> 3.19 deg)."""
    fit0, choice = start_model[0], dict(start_model[1])
    if choice.get("model") != "lobe":
        return dict(fit0), 0, choice
    profile = px.profile_of(fsel)        # drawn as `Pixels.choose_model` draws them
    solve = px.solver(profile)
    e, lights, ok = px.gather(profile), px.lights_of(profile), px.all_ok[profile]
    vm = fit0["volume_model"]
    start = {v: dict(sigma=fit0["sigma"], n_i=fit0["n_i"], volume_model=v, gain=1.0,
                     normals=solve(fit0["sigma"], fit0["n_i"], v, search=False))
             for v in ((vm,) if is_metal(fit0["n_i"]) else dict.fromkeys((vm, *px.settings.diffuse_models)))}
    best = start[vm]
    fit, warm = _warm_up(e, lights, ok, solve, best)
    if _has_interface(fit) and not is_metal(fit["n_i"]) and len(start) > 1:
        best, fit, more = _diffuse_at_fits(e, lights, ok, solve, px.check_of(pix), start, best, fit, choice)
        warm, vm = warm + more, best["volume_model"]
    if not _has_interface(fit):
        choice.update(model="lambertian", why=f"the earlier solve's lobe (σ {fit0['sigma']:.3f}, n_i "
                      f"{fit0['n_i']:.2f}, {diffuse_name(vm)} diffuse) refitted here ends at n_i {fit['n_i']:.3f}: "
                      "no interface")
        return dict(fit, sigma=LAMBERTIAN_SIGMA, n_i=1.0, volume_model=vm), warm, choice
    choice.update(lobe_sigma=fit["sigma"], lobe_n_i=fit["n_i"], diffuse=diffuse_name(vm))
    return dict(fit, volume_model=vm), warm, choice
