"""BRDF-aware photometric stereo: normals and the LI model estimated in alternation.

Layer: this module calls photometric stereo (facette.recon) and identifies BRDF parameters, so it
lives in facette.fit, which may import recon and brdf (recon may not import fit). It is offered
by name in the one table of photometric-stereo methods, `facette.methods` (a layer above),
as `photometric_stereo(method="li_alternating")`.

    ps_li_alternating(images, light_dirs, ...) -> PSResult

1. Robust initial normals (the thesis's hierarchical elimination by default).
2. Fit the LI model's shared (σ, n_i) on the pixels whose normals are most trustworthy, with
   K_d per pixel and channel solved in closed form for every (σ, n_i) (variable projection:
   E = A + B κ is linear in κ, facette.brdf.li_shading_terms), robust loss (soft-L1 on the
   relative residual): `fit_li_per_pixel_kd`.
3. Re-estimate each pixel's normal and K_d against the fitted model, all lights, robust
   (facette.fit.refine_normals_li). Pixels the Lambertian model already explains (least-squares
   relative residual below t_residual, every light usable, no light inside the fitted specular
   lobe) skip this step; a material whose fit finds n_i → 1 (no interface: Lambertian-like)
   skips it entirely. That choice is made once, in round 1, by the profile of the fit pixels'
   robust cost (`_profile_lobe`): for each diffuse part (the LI substrate, eq 3.15, or a
   Lambertian term beside the lobe as in Cook–Torrance) and each (σ, n_i) of a coordinate search,
   the fit pixels' normals are solved against the model and the summed robust cost of the best
   explained 80 % of them scores it (a pixel whose solve stopped in a wrong minimum does not
   decide). The material gets a lobe when the best lowers that cost by ≥ LOBE_MIN_GAIN against the
   Lambertian solution (renders: plaster −20 to +4.6 %, paints and satin 74–99 %), with the
   diffuse part of the best; (σ, n_i) are then fitted from the best point on the initial normals
   and warmed up (normals against the fit, refit) until they settle. Round 1's fit pixels are
   drawn from the brighter half (the better signal to noise: a dark glossy table, whose relative
   values the highlight dominates, pulled the simulated scan's fit to σ 0.035, n_i 1.15). The
   costs are in `info["materials"][k]["model_choice"]`.
4. Refit and repeat until the median normal change of the re-estimated pixels is below
   tol_deg, or after `rounds` rounds. Each round's change is in `info["rounds"]`.

Large images (more than `coarse_pixels` valid pixels, one material): steps 1–4 run on the images
binned f × f; at full size the fitted (σ, n_i) are kept and each pixel of the BRDF-aware level
gets a few Levenberg–Marquardt steps from the upsampled coarse normal (`info["coarse"]`, and the
"full size" entry of `info["rounds"]`). At 2144×1424 × 12 this takes the BRDF-aware part from
~245 to ~20 CPU s for 0.03° of mean error on tiled Mitsuba scenes (128 px objects; no loss at f = 2).

Several materials: with materials="auto", the valid pixels are split by k-means (k = 2) on
their chromaticity and log Lambertian albedo (the initial solution's), each region at least
min_region_fraction of the pixels; each region gets its own (σ, n_i), and two regions whose fits
agree (|Δσ| < 15 % and |Δn_i| < 0.03) are merged back. `info["materials"]` lists each region's
parameters and pixel count.
"""
import time

import numpy as np

from facette.brdf import kd_from_kappa, li_shading_terms
from facette.recon import PSResult, ps_rank_trimmed, ps_woodham1980
from facette.recon._ps import T_RESIDUAL, _check_inputs, _pixel_dirs, _run_blocks, _usable
from ._li_model import (DIFFUSE, LI_VOLUME_MODEL, PROFILE_TABLE_GRID, PROFILE_VALUES, choose_material_model,
                        diffuse_name, fit_li_per_pixel_kd)
from ._normals_li import RefineResult, refine_normals_li

__all__ = ["ps_li_alternating"]

LOBE_TAN = 2.5             # a light is inside the lobe when tan θ_h < LOBE_TAN σ (D > 0.2 % of its peak)
COARSE_PIXELS = 250_000    # above this many valid pixels the alternation runs coarse-to-fine
FINE_START_DEG = 5.0       # the fine round starts from the initial normal where the coarse one is this far
FINE_STEP_TOL = 1e-3       # rad (0.06°): full-size steps stop below this (errors are ~1°)
ROUND_STEP_TOL = 1e-3      # rad (0.06°): a pixel's solve stops below this step in the rounds too
SETTLED_SIGMA = 0.05       # a later round's refit within 5 % of σ and 0.01 of n_i: no new re-estimate
SETTLED_N_I = 0.01
_BLOCK = 32768             # pixels per block of the per-pixel solve (array code, two threads)
_BLOCK_COMPILED = 262144   # pixels per call of the compiled solve (it threads inside)


def _settled(prev, new):
    """Whether a refit (σ, n_i) is within SETTLED_SIGMA (relative) and SETTLED_N_I of the previous."""
    return abs(new[0] - prev[0]) <= SETTLED_SIGMA * max(prev[0], 1e-3) and abs(new[1] - prev[1]) <= SETTLED_N_I


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1, 1)))


def _in_lobe(normals, lights, sigma):
    """(N,) True where some light is inside the fitted lobe (tan θ_h < LOBE_TAN σ)."""
    v = np.float32([0, 0, 1])
    h = lights + v
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    ch = normals @ h.T if h.ndim == 2 else np.einsum("nj,nmj->nm", normals, h)
    # tan θ_h < k  ⟺  cos² θ_h > 1 / (1 + k²) (for cos θ_h > 0): no square root per pair
    k2 = np.float32((LOBE_TAN * sigma) ** 2)
    return np.any(ch > np.float32(np.sqrt(1 / (1 + k2))), axis=1)


def _lambertian_correction(normals, lights, sigma, n_i, volume_model, grid=65):
    """(N, 3) corrected normals for pixels outside the lobe, from least-squares normals.

    Outside the specular lobe the model is E ≈ B(n, s) κ, whose least-squares (Lambertian)
    normal n_LS(n) differs from n by a smooth bias (the Fresnel transmissions of the volume
    part, eq 3.15, tilt it by up to a few degrees at oblique normals). That bias depends on the
    normal alone (κ cancels), so it is tabulated once per (σ, n_i) on a grid of normals and
    interpolated: n ≈ n_LS + (n_grid − n_LS(n_grid)) at n_grid = n_LS. Cost: grid² pixels, not N.
    lights : (m, 3), or (N, m, 3) whose mean direction is used (near lights vary little).
    """
    s = lights if lights.ndim == 2 else lights.mean(axis=0)
    s = s / np.linalg.norm(s, axis=1, keepdims=True)
    u = np.linspace(-1, 1, grid, dtype=np.float32)
    gx, gy = np.meshgrid(u, u)
    r2 = gx * gx + gy * gy
    inside = r2 < 0.995
    gn = np.stack([gx, gy, np.sqrt(np.maximum(1 - r2, 0))], axis=-1).reshape(-1, 3)
    gn[~inside.ravel()] = [0, 0, 1]
    _, b = li_shading_terms(gn, s, sigma, n_i, specular=False, volume_model=volume_model)
    g = b @ np.linalg.pinv(s).T.astype(np.float32)                 # least squares of the model's values
    n_ls = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
    delta = (gn - n_ls).reshape(grid, grid, 3)
    delta[~inside] = 0
    # bilinear lookup at each pixel's own (least-squares) normal
    fx = np.clip((normals[:, 0] + 1) / 2 * (grid - 1), 0, grid - 1.001)
    fy = np.clip((normals[:, 1] + 1) / 2 * (grid - 1), 0, grid - 1.001)
    ix, iy = fx.astype(int), fy.astype(int)
    wx, wy = (fx - ix)[:, None], (fy - iy)[:, None]
    d = ((1 - wx) * (1 - wy) * delta[iy, ix] + wx * (1 - wy) * delta[iy, ix + 1]
         + (1 - wx) * wy * delta[iy + 1, ix] + wx * wy * delta[iy + 1, ix + 1])
    out = normals + d
    return (out / np.linalg.norm(out, axis=1, keepdims=True)).astype(np.float32)


def _regions(albedo, n_pix, materials, min_fraction, seed):
    """(N,) region label per pixel: 0 for one material; k-means on chromaticity + log albedo."""
    if materials in (1, None) or n_pix < 50:
        return np.zeros(n_pix, np.int64), "one material"
    from scipy.cluster.vq import kmeans2
    tot = np.maximum(albedo.sum(1, keepdims=True), 1e-6)
    feat = np.concatenate([albedo / tot, np.log(tot)], axis=1) if albedo.shape[1] > 1 else np.log(tot)
    feat = (feat - feat.mean(0)) / np.maximum(feat.std(0), 1e-6)
    k = 2 if materials == "auto" else int(materials)
    _, lab = kmeans2(feat.astype(np.float64), k, seed=seed, minit="++")
    counts = np.bincount(lab, minlength=k)
    small = counts < min_fraction * n_pix
    if small.all() or (k - small.sum()) < 2:
        return np.zeros(n_pix, np.int64), "one material (the clusters were too small)"
    if small.any():   # small clusters go to the nearest big one
        big = np.flatnonzero(~small)
        cent = np.stack([feat[lab == j].mean(0) for j in big])
        far = np.isin(lab, np.flatnonzero(small))
        lab[far] = big[np.argmin(((feat[far, None, :] - cent[None]) ** 2).sum(-1), axis=1)]
    _, lab = np.unique(lab, return_inverse=True)
    return lab.astype(np.int64), f"{lab.max() + 1} regions by k-means on chromaticity and log albedo"


def ps_li_alternating(images, light_dirs, mask=None, channel=None, saturation=None,
                      init=ps_rank_trimmed, rounds=4, tol_deg=0.1, fit_pixels=1000,
                      t_residual=T_RESIDUAL, iterations=24, materials=1, min_region_fraction=0.05,
                      seed=0, init_options=None, coarse_pixels=COARSE_PIXELS, fine_iterations=2,
                      engine="auto", volume_model=LI_VOLUME_MODEL, highlight_start="all",
                      diffuse="auto"):
    """BRDF-aware photometric stereo with the LI model (module doc).

    images : (m, H, W) or (m, H, W, C) float, linear, divided by each light's intensity, m ≥ 4.
    light_dirs : (m, 3) unit vectors towards the lights, or (H, W, m, 3) per pixel (near lights,
        fall-off already divided out of the images).
    mask, channel, saturation : as `ps_woodham1980`.
    init : photometric-stereo function for the starting normals (default `ps_rank_trimmed`; or
        `ps_hierarchical_tautzia2016`, `ps_woodham1980`, ...; by name through
        `facette.methods.photometric_stereo`); init_options : its keyword arguments.
        On the 17 Mitsuba scenes at 256 spp the rank_trimmed start is better than the hierarchy's
        on 11 (sphere paint 0.10: 1.14 against 1.29 deg; the relief paint 0.05: 0.59 against 0.96;
        the thesis test 0.97 / 0.87 / 0.74 against 1.01 / 1.01 / 1.14 deg), equal on 4 and worse
        on the two satins (sphere 3.10 against 2.51, relief 1.51 against 1.14).
    rounds : at most this many fit → re-estimate rounds; tol_deg : stop when the median
        normal change of the re-estimated pixels is below this (degrees).
    fit_pixels : pixels (per material) whose values feed the (σ, n_i) fit, drawn among the
        most trustworthy (round 1: the initial solution's valid pixels not too oblique; later:
        the half best explained by the model).
    t_residual : pixels whose least-squares relative residual is below this, with every light
        usable and none in the fitted lobe, keep their initial normal (Lambertian level).
    iterations : at most this many Gauss–Newton steps per round per pixel (a pixel stops once
        its step is below the solver's tolerance). 24, not 8: the cap stopped pixels before they
        converged (Mitsuba sphere paint 0.10, 256 spp: 1.139 / 1.114 / 1.102 deg at 8 / 16 / 24;
        near lights 1.243 / 1.190 / 1.165; DiLiGenT, 96 lights: 9.50 / 9.31 deg at 8 / 24) at
        no measurable cost on the 12 MP simulated scan (20.1 / 17.7 s, one run each).
    materials : 1 (one material), "auto" (regions found by clustering, see module doc) or an int.
    coarse_pixels : coarse-to-fine above this many valid pixels (one material only): the whole
        alternation runs on the images binned by the smallest integer factor that brings the
        valid pixels below it; at full size the fitted (σ, n_i) are kept and each pixel that
        needs the BRDF-aware step gets `fine_iterations` Levenberg–Marquardt steps from the
        upsampled coarse normal (a second start from the pixel's own initial normal, tried where
        the coarse normals bend by > 4° around the cell, made the tiled Mitsuba test worse:
        1.081° against 1.069° mean). None or 0: never.
    engine : the per-pixel solver of `refine_normals_li` ("auto", "compiled", "arrays").
    volume_model : the LI volume part, "tables" (eq 3.15, default: LI_VOLUME_MODEL) or "approx"
        (eq 3.49–3.57); see LI_VOLUME_MODEL for the figures.
    highlight_start : "all" (default): every pixel with a highlight also gets a second start, the
        half-vector of its brightest light above the Lambertian prediction, and keeps the solve of
        lower robust cost; "subsample": the fit pixels only (their warm-up), every other pixel
        starts from its robust initial normal alone, about half the time of the per-pixel solve.
        Through `process` (DiLiGenT crops, 96 lights): cat 5.69° / 68 CPU s ("all") against
        5.72° / 35 CPU s ("subsample"), reading 10.98° / 33 s against 12.32°; the kernel alone on
        cat with (σ, n_i) fixed: 5.72° at 21.7 CPU s against 5.78° at 8.6 s; choosing, before any
        step, the start of lower cost was worse than either (5.83°). "all" is the default because
        it is what held up on the unseen objects of issue 24.
    diffuse : the diffuse part beside the lobe: "li" (the LI substrate, `volume_model`), "lambert"
        (Lambertian, no transmission: Cook–Torrance) or "auto" (default): per material, the one
        whose best lobe has the lower trimmed profile cost on the fit pixels (DIFFUSE,
        `_profile_lobe`; info["materials"][k]["diffuse"] and its "model_choice").
    Returns a `PSResult` (method "li_alternating"): albedo is K_d (a reflectance, per channel);
    info holds "rounds" (per round: σ, n_i, pixels fitted and re-estimated, median change,
    seconds), "materials" (per region: σ, n_i, pixel count, whether the BRDF step ran) and
    "levels" (pixels handled and seconds of the initial solution, of the Lambertian level and
    of the BRDF-aware step).
    """
    t_start = time.perf_counter()
    images, light_dirs, mask, channel = _check_inputs(images, light_dirs, mask, channel)
    m, h, w, c = images.shape
    if rounds < 1:
        raise ValueError(f"rounds = {rounds}: give at least 1 fit / re-estimate round")
    if not callable(init):      # a name is looked up by facette.methods, the layer above
        raise TypeError(f"init = {init!r}: give a photometric-stereo function (ps_rank_trimmed, ...); by name: "
                        "facette.methods.photometric_stereo(..., method='li_alternating', init=NAME)")
    if highlight_start not in ("all", "subsample"):
        raise ValueError(f"highlight_start = {highlight_start!r}: choose 'all' or 'subsample'")
    if diffuse not in ("auto", *DIFFUSE):
        raise ValueError(f"diffuse = {diffuse!r}: choose 'auto', {', '.join(repr(k) for k in DIFFUSE)}")
    diffuse_models = tuple(dict.fromkeys([volume_model if k == "li" else DIFFUSE[k] for k in
                                          (("li", "lambert") if diffuse == "auto" else (diffuse,))]))
    vm = diffuse_models[0]      # the current material's diffuse part (read by the steps below)
    if init is ps_li_alternating:
        raise ValueError("init = 'li_alternating': the initial normals must come from another method "
                         "(hierarchical_tautzia2016, woodham1980, rpca_wu2010, ...)")
    coarse = None
    n_valid_in = int(mask.sum())
    if coarse_pixels and materials in (1, None) and n_valid_in > coarse_pixels:
        f = int(np.ceil(np.sqrt(n_valid_in / coarse_pixels)))
        ci, cl, cm = _bin_inputs(images, light_dirs, mask, f, saturation)
        t_c, c_c = time.perf_counter(), time.process_time()
        coarse = ps_li_alternating(ci, cl, mask=cm, channel=channel, saturation=None, init=init,
                                   rounds=rounds, tol_deg=tol_deg, fit_pixels=fit_pixels,
                                   t_residual=t_residual, iterations=iterations, materials=1,
                                   seed=seed, init_options=init_options, coarse_pixels=None,
                                   engine=engine, volume_model=volume_model, highlight_start=highlight_start,
                                   diffuse=diffuse)
        coarse.info["factor"] = f
        coarse.info["seconds"] = time.perf_counter() - t_c
        coarse.info["cpu_seconds"] = time.process_time() - c_c
    opts = dict(init_options or {})
    base = init(images, light_dirs, mask=mask, channel=channel, saturation=saturation, **opts)
    t_init = time.perf_counter() - t_start
    res = PSResult(normal=base.normal.copy(), albedo=base.albedo.copy(), valid=base.valid.copy(),
                   n_triplets=base.n_triplets, shadow=base.shadow.copy(), specular=base.specular.copy(),
                   residual=base.residual.copy(), skipped=np.ones((h, w), bool), method="li_alternating")
    idx = np.flatnonzero(base.valid.ravel())
    info = {"init": base.method, "rounds": [], "materials": [], "pixels": int(idx.size)}
    res.info = info
    if idx.size == 0:
        info["levels"] = {"init": {"pixels": 0, "seconds": t_init}}
        return res
    flat = images.reshape(m, h * w, c)
    s_all = _pixel_dirs(light_dirs, idx)                          # (m, 3) or (N, m, 3)
    nrm = base.normal.reshape(-1, 3)[idx].astype(np.float32)
    nrm0 = nrm.copy()
    # the Lambertian level: least squares over every light (its residual decides which pixels it
    # explains; the init's own residual is on the lights that method kept, and its normal would
    # bias the tabulated correction, which models least squares over every light)
    ls = base if init is ps_woodham1980 else \
        ps_woodham1980(images, light_dirs, mask=mask, channel=channel, saturation=saturation)
    nrm_ls = ls.normal.reshape(-1, 3)[idx].astype(np.float32)
    resid_ls = np.where(ls.valid.reshape(-1)[idx], ls.residual.reshape(-1)[idx], np.inf)
    alb = base.albedo.reshape(-1, c)[idx]
    g_ok = _usable(flat[:, idx, channel], saturation).T            # (N, m)
    all_ok = np.all(np.isfinite(flat[:, idx, :]), axis=2).T & g_ok
    resid0 = base.residual.reshape(-1)[idx]
    rng = np.random.default_rng(seed)
    labels, how = _regions(alb, idx.size, materials, min_region_fraction, seed)
    info["regions_found_by"] = how
    kd = np.zeros((idx.size, c), np.float32)
    refined = np.zeros(idx.size, bool)
    shadow_new = base.shadow.reshape(-1, m)[idx].copy()
    rel = resid0.copy()
    t_brdf = 0.0
    mats = []

    def gather(sel):
        return np.ascontiguousarray(np.transpose(flat[:, idx[sel], :], (1, 0, 2)), dtype=np.float32)

    def lights_of(sel):
        return s_all if s_all.ndim == 2 else s_all[sel]

    has_highlight, hl_start = _highlight_starts(flat[:, idx, channel].T, all_ok, nrm, s_all, alb[:, channel])

    def refine(sel, sigma, n_i, first_round=True, engine=engine, step_tol=ROUND_STEP_TOL, diffuse_vm=None,
               table_grid=None):
        # first round: the current normal and the highlight start; later rounds start from the
        # previous round's normals, already near, so one start and fewer steps do. Pixel blocks
        # on WORKERS threads (numpy releases the GIL in its loops).
        out = {}
        vm_ = vm if diffuse_vm is None else diffuse_vm      # the current material's, unless given

        def block(a):
            sub = sel[a:a + (_BLOCK if s_all.ndim == 3 else _BLOCK_COMPILED)]
            if first_round:
                # the highlight start doubles the cost where it is tried (most pixels under 96 lights):
                # on every pixel only with highlight_start="all" (module doc)
                hl = has_highlight[sub] if (highlight_start == "all" or sel.size <= 4 * fit_pixels) \
                    else np.zeros(sub.size, bool)
                out[a] = refine_normals_li(gather(sub), lights_of(sub), nrm[sub], sigma, n_i,
                                           usable=all_ok[sub], iterations=iterations,
                                           extra_starts=[hl_start[sub]] if hl.any() else None, extra_rows=hl,
                                           engine=engine, volume_model=vm_, step_tol=step_tol, table_grid=table_grid)
            else:
                out[a] = refine_normals_li(gather(sub), lights_of(sub), nrm[sub], sigma, n_i,
                                           usable=all_ok[sub], iterations=max(2, iterations // 2), engine=engine,
                                           volume_model=vm_, step_tol=step_tol)

        if s_all.ndim == 2:
            # the compiled per-pixel solve runs its own threads: blocks in turn (memory only)
            for a in range(0, sel.size, _BLOCK_COMPILED):
                block(a)
        else:
            _run_blocks(block, range(0, sel.size, _BLOCK))
        parts = [out[a] for a in sorted(out)]
        return RefineResult(**{k: np.concatenate([getattr(p, k) for p in parts])
                               for k in ("normals", "kd", "used", "rel_residual")})

    def split_levels(pix, sigma, n_i):
        # the BRDF-aware step where the lobe matters; the rest keeps the initial solution (its
        # shadow test) unless least squares already explained it (then corrected here)
        lobe = _in_lobe(nrm0[pix], lights_of(pix), sigma) | has_highlight[pix]
        lam_ok = (resid_ls[pix] < t_residual) & all_ok[pix].all(1) & ~lobe
        lam_pix = pix[lam_ok]
        if lam_pix.size:
            nrm[lam_pix] = _lambertian_correction(nrm_ls[lam_pix], lights_of(lam_pix), sigma, n_i, vm)
            refined[lam_pix] = False
        return lobe, lam_ok, pix[~lam_ok & lobe]

    def choose_model(fsel):
        # Round 1 (`choose_material_model`): lobe or none, which diffuse part, and (σ, n_i), on the
        # profile pixels: the fit pixels, fewer under many lights (PROFILE_VALUES values)
        fsel = fsel[np.sort(rng.choice(fsel.size, min(fsel.size, max(100, PROFILE_VALUES // m)), replace=False))]
        e_f = gather(fsel)
        l_f, ok_f = lights_of(fsel), all_ok[fsel]
        warm_engine = "arrays" if engine == "auto" else engine
        # the search's solves: the compiled engine where it applies (distant lights), on a coarse
        # table of the volume part (PROFILE_TABLE_GRID), converged, with the highlight start (one
        # start and half the steps moved the simulated scan's choice from σ 0.050, n_i 1.20 to
        # 0.035, 1.30: 0.38° -> 0.62°)
        search_engine = "compiled" if engine == "auto" and s_all.ndim == 2 else warm_engine

        def solve(sigma, n_i, vm_, search=True):
            return refine(fsel, sigma, n_i, engine=search_engine if search else warm_engine, diffuse_vm=vm_,
                          table_grid=PROFILE_TABLE_GRID if search else None).normals

        return choose_material_model(e_f, l_f, ok_f, solve, diffuse_models)

    def lambertian_material(pix):
        # no interface: least squares over every light is the Lambertian answer where it explains
        # the pixel (every light usable, residual < t_residual); a robust init's trimming only adds
        # noise there (Mitsuba plaster relief: least squares 1.41°, rank_trimmed 1.54°)
        lam = pix[(resid_ls[pix] < t_residual) & all_ok[pix].all(1)]
        nrm[lam] = nrm_ls[lam]
        return int(lam.size)

    def store(todo, rr):
        nrm[todo] = rr.normals
        kd[todo] = rr.kd
        refined[todo] = True
        rel[todo] = rr.rel_residual
        shadow_new[todo] = all_ok[todo] & ~rr.used

    def _fine_round(x0, pix, steps=None):
        # full size after the coarse pass: (σ, n_i) kept, a few steps from the upsampled normal
        t_r, c_r = time.perf_counter(), time.process_time()
        sigma, n_i = x0
        up = _upsample_normals(coarse.normal, (h, w), coarse.info["factor"]).reshape(-1, 3)[idx]
        # at a silhouette the upsampled normal blends the object's rim with the table's, and a few
        # steps do not bring it back (the simulated 12 MP scan: a 3° ring round its sphere, heights
        # 0.45 mm off); where it is > FINE_START_DEG from the pixel's own initial normal, that is the start
        up = np.where((_angle_deg(up, nrm0) > FINE_START_DEG)[:, None], nrm0, up)
        lobe, lam_ok, todo = split_levels(pix, sigma, n_i)
        change = np.zeros(0)
        if todo.size:
            out = []
            for a in range(0, todo.size, _BLOCK_COMPILED if s_all.ndim == 2 else _BLOCK):
                sub = todo[a:a + (_BLOCK_COMPILED if s_all.ndim == 2 else _BLOCK)]
                out.append(refine_normals_li(gather(sub), lights_of(sub), up[sub], sigma, n_i,
                                             usable=all_ok[sub], iterations=steps or fine_iterations,
                                             step_tol=FINE_STEP_TOL, engine=engine, volume_model=vm))
            rr = RefineResult(**{k: np.concatenate([getattr(p, k) for p in out])
                                 for k in ("normals", "kd", "used", "rel_residual")})
            mean_its = float(np.average([getattr(p, "mean_iterations", p.iterations) for p in out],
                                        weights=[len(p.normals) for p in out]))
            change = _angle_deg(rr.normals, up[todo])
            store(todo, rr)
        info["rounds"].append({"material": 0, "round": "full size", "sigma": sigma, "n_i": n_i,
                               "pixels_refined": int(todo.size), "pixels_lambertian": int(lam_ok.sum()),
                               "pixels_initial_kept": int((~lam_ok & ~lobe).sum()),
                               "median_change_deg": float(np.median(change)) if change.size else 0.0,
                               "mean_change_deg": float(change.mean()) if change.size else 0.0,
                               "mean_iterations": mean_its if todo.size else 0.0,
                               "seconds": time.perf_counter() - t_r,
                               "cpu_seconds": time.process_time() - c_r})

    if coarse is not None:
        info["coarse"] = {"factor": coarse.info["factor"], "pixels": coarse.info["pixels"],
                          "seconds": coarse.info["seconds"],
                          "cpu_seconds": coarse.info["cpu_seconds"], "rounds": coarse.info["rounds"]}
    for region in range(int(labels.max()) + 1):
        t_reg = time.perf_counter()
        pix = np.flatnonzero(labels == region)
        x0 = None
        mat = {"region": region, "pixels": int(pix.size), "brdf_step": True}
        trust = pix[nrm[pix, 2] > 0.3]
        if trust.size < 10:
            trust = pix
        if trust.size >= 20:     # round 1 draws from the brighter half: the better signal to noise
            a_t = alb[trust, channel]
            trust = trust[a_t >= np.median(a_t)]
        score = None
        vm = diffuse_models[0]
        if coarse is not None:
            cmat = coarse.info["materials"][0] if coarse.info.get("materials") else {"brdf_step": False}
            vm = cmat.get("volume_model", vm)
            if "model_choice" in cmat:     # made on the coarse images: say so at full size too
                mat["model_choice"] = dict(cmat["model_choice"], made_on="the coarse pass")
            full = None
            if not cmat.get("brdf_step") or cmat.get("sigma") is None:
                # binning smears a sharp highlight over its block, and the lobe no longer fits it:
                # a glossy sphere at 2144x1424 binned by 4 showed a 1.9 % gain (Lambertian), 67 % at
                # 536x356 unbinned. So "no lobe" is asked again of full-size pixels.
                fsel = np.sort(rng.choice(trust, min(fit_pixels, trust.size), replace=False))
                fit, _, choice = choose_model(fsel)
                if choice["model"] == "lobe":
                    full = fit
                    vm = fit["volume_model"]
                    mat["model_choice"] = dict(choice, made_on="full-size pixels (the coarse pass found no lobe)")
            if full is not None:
                x0 = (full["sigma"], full["n_i"])
                _fine_round(x0, pix, steps=iterations)   # the coarse normals are Lambertian ones: converge
            elif not cmat.get("brdf_step") or cmat.get("sigma") is None:
                mat.update(brdf_step=False, note="coarse pass: " + cmat.get("note", "no BRDF step"))
                lambertian_material(pix)
                if cmat.get("sigma") is not None:
                    x0 = (cmat["sigma"], cmat["n_i"])
            else:
                x0 = (cmat["sigma"], cmat["n_i"])
                _fine_round(x0, pix)
            rounds_here = 0
        else:
            rounds_here = int(rounds)
        for rnd in range(1, rounds_here + 1):
            t_r, c_r = time.perf_counter(), time.process_time()
            if score is not None:   # later rounds: all but the worse-explained half of the re-estimated
                trust = pix[score <= np.median(score[np.isfinite(score)])] if np.isfinite(score).any() else pix
            fsel = np.sort(rng.choice(trust, min(fit_pixels, trust.size), replace=False))
            warm, choice = 0, None
            if rnd == 1:           # the model choice gathers its own (profile) pixels' values
                fit, warm, choice = choose_model(fsel)
                vm = fit["volume_model"]
            else:
                fit = fit_li_per_pixel_kd(gather(fsel), lights_of(fsel), nrm[fsel], all_ok[fsel], x0=x0,
                                          volume_model=vm)
            if not np.isfinite(fit["sigma"]):
                mat.update(brdf_step=False, note=f"fit failed: {fit['message']}")
                break
            settled = x0 is not None and rnd > 1 and _settled(x0, (fit["sigma"], fit["n_i"]))
            x0 = (fit["sigma"], fit["n_i"])
            round_info = {"material": region, "round": rnd, "sigma": fit["sigma"], "n_i": fit["n_i"],
                          "fit_pixels": int(fsel.size), "warm_up_refits": warm}
            if settled:
                # the refit on the re-estimated normals barely moved the model: re-estimating every
                # pixel against it again would move them by less than the noise (module doc)
                round_info.update(pixels_refined=0, median_change_deg=0.0, stopped="(σ, n_i) settled",
                                  seconds=time.perf_counter() - t_r, cpu_seconds=time.process_time() - c_r)
                info["rounds"].append(round_info)
                break
            if choice is not None:
                round_info["model_choice"] = choice
                mat["model_choice"] = choice
            if choice is not None and choice["model"] == "lambertian":
                n_ls = lambertian_material(pix)
                round_info.update(pixels_refined=0, pixels_lambertian=n_ls, median_change_deg=0.0,
                                  seconds=time.perf_counter() - t_r)
                info["rounds"].append(round_info)
                mat.update(brdf_step=False, note=f"Lambertian-like ({choice['why']}): BRDF step skipped, "
                           "least squares where it explains the pixel, the initial normals elsewhere")
                break
            lobe, lam_ok, todo = split_levels(pix, fit["sigma"], fit["n_i"])
            change = np.zeros(0)
            if todo.size:
                rr = refine(todo, fit["sigma"], fit["n_i"], first_round=not refined[todo].all())
                change = _angle_deg(rr.normals, nrm[todo])
                store(todo, rr)
            sc = np.full(pix.size, np.inf, np.float32)     # Lambertian-level pixels: not for the fit
            sc[~lam_ok & lobe] = rel[todo]
            score = sc
            med = float(np.median(change)) if change.size else 0.0
            round_info.update(pixels_refined=int(todo.size), pixels_lambertian=int(lam_ok.sum()),
                              pixels_initial_kept=int((~lam_ok & ~lobe).sum()),
                              median_change_deg=med,
                              mean_change_deg=float(change.mean()) if change.size else 0.0,
                              seconds=time.perf_counter() - t_r, cpu_seconds=time.process_time() - c_r)
            info["rounds"].append(round_info)
            if med < tol_deg:
                break
        mat.update(sigma=x0[0] if x0 else None, n_i=x0[1] if x0 else None, volume_model=vm,
                   diffuse=diffuse_name(vm),
                   pixels_refined=int(refined[pix].sum()), seconds=time.perf_counter() - t_reg)
        # K_d of the pixels that kept their Lambertian solution: ρ/π = κ × I at normal incidence
        keep = pix[~refined[pix]]
        if keep.size and x0 is not None and x0[1] >= 1.0:
            _, b0 = li_shading_terms(np.float32([[0, 0, 1]]), np.float32([[0, 0, 1]]), x0[0], x0[1],
                                     volume_model=vm)
            kd[keep] = kd_from_kappa(alb[keep] / np.pi / max(float(b0[0, 0]), 1e-6), x0[1], vm)
        elif keep.size:
            kd[keep] = np.clip(alb[keep], 0, 1)
        t_brdf += time.perf_counter() - t_reg
        mats.append(mat)
    info["materials"] = _merge_agreeing(mats)
    _scatter_rows(res.normal, idx, nrm)
    _scatter_rows(res.albedo, idx, kd)
    _scatter_rows(res.shadow, idx, shadow_new)
    _scatter_rows(res.residual, idx, rel)
    sk = res.skipped.reshape(-1)
    sk[:] = False
    sk[idx] = ~refined
    spec = res.specular.reshape(-1, m)
    spec[idx[refined]] = False     # the model explains the highlights: no light eliminated
    info["levels"] = {
        "init": {"method": base.method, "pixels": int(idx.size), "seconds": t_init},
        "lambertian": {"pixels": int((~refined).sum())},
        "brdf_aware": {"pixels": int(refined.sum()), "seconds": t_brdf},
    }
    info["seconds"] = time.perf_counter() - t_start
    return res


def _highlight_starts(values, usable, normals, lights, albedo):
    """A second start per pixel: the half-vector of the light that most exceeds the Lambertian
    prediction of the initial solution (a highlight says where the normal is), tried where that
    light stands out (≥ 10 % of the pixel's mean value). values, usable : (N, m); normals (N, 3);
    lights (m, 3) or (N, m, 3); albedo (N,). Returns (has_highlight (N,) bool, starts (N, 3))."""
    lam_pred = (normals @ lights.T if lights.ndim == 2 else np.einsum("nj,nmj->nm", normals, lights)) * \
        (albedo / np.pi)[:, None]
    excess = np.where(usable, values, -np.inf) - lam_pred
    brightest = np.argmax(excess, axis=1)
    mean_v = np.nanmean(np.where(usable, values, np.nan), axis=1)
    has_highlight = np.take_along_axis(excess, brightest[:, None], 1)[:, 0] > 0.1 * np.nan_to_num(mean_v)
    half = lights + np.float32([0, 0, 1])
    half = (half / np.linalg.norm(half, axis=-1, keepdims=True)).astype(np.float32)
    return has_highlight, (half[brightest] if half.ndim == 2 else half[np.arange(len(normals)), brightest])


def _bin_inputs(images, light_dirs, mask, f, saturation):
    """Images (m, H, W, C), directions and mask binned by f × f blocks (H, W padded up).

    A binned value is the mean of the block's masked, finite (and, with `saturation`, unsaturated)
    values; NaN where fewer than half the block's pixels are such. The binned mask: at least half
    the block's pixels masked. Per-pixel directions: the block mean, renormalised."""
    m, h, w, c = images.shape
    hc, wc = -(-h // f), -(-w // f)

    from ._normals_li_jit import bin_images   # numba loads only when li_alternating runs

    msk = np.pad(mask, [(0, hc * f - h), (0, wc * f - w)])
    cmask = msk.reshape(hc, f, wc, f).sum((1, 3)) * 2 >= f * f
    out = bin_images(images, mask, f, saturation)
    if light_dirs.ndim == 2:
        dirs = light_dirs
    else:
        ld = np.pad(light_dirs, [(0, hc * f - h), (0, wc * f - w), (0, 0), (0, 0)], mode="edge")
        dirs = ld.reshape(hc, f, wc, f, m, 3).mean((1, 3))
        dirs = (dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)).astype(np.float32)
    return out, dirs, cmask


def _upsample_normals(coarse, shape, f):
    """(H, W, 3) unit normals bilinearly interpolated from the (hc, wc, 3) coarse normals (cell
    centres); coarse pixels without a normal take their nearest valid neighbour's first."""
    from scipy.ndimage import distance_transform_edt, map_coordinates
    valid = np.linalg.norm(coarse, axis=-1) > 0.5
    if not valid.any():
        return np.zeros(shape + (3,), np.float32)
    if not valid.all():
        _, (iy, ix) = distance_transform_edt(~valid, return_indices=True)
        coarse = coarse[iy, ix]
    h, w = shape
    yy = (np.arange(h, dtype=np.float32) + 0.5) / f - 0.5
    xx = (np.arange(w, dtype=np.float32) + 0.5) / f - 0.5
    gy, gx = np.meshgrid(yy, xx, indexing="ij")
    out = np.stack([map_coordinates(coarse[..., k], [gy, gx], order=1, mode="nearest")
                    for k in range(3)], -1)
    ln = np.linalg.norm(out, axis=-1, keepdims=True)
    return np.where(ln > 1e-6, out / np.maximum(ln, 1e-6), np.float32([0, 0, 1])).astype(np.float32)


def _merge_agreeing(mats):
    """Regions whose fitted (σ, n_i) agree (|Δσ| < 15 %, |Δn_i| < 0.03) are one material: one
    entry with the summed pixel counts and the pixel-weighted parameters."""
    out = []
    for mat in mats:
        for other in out:
            if (mat.get("sigma") is not None and other.get("sigma") is not None
                    and mat["brdf_step"] == other["brdf_step"] and mat.get("diffuse") == other.get("diffuse")
                    and abs(mat["sigma"] - other["sigma"]) < 0.15 * max(other["sigma"], 1e-3)
                    and abs(mat["n_i"] - other["n_i"]) < 0.03):
                n1, n2 = other["pixels"], mat["pixels"]
                for k in ("sigma", "n_i"):
                    other[k] = (other[k] * n1 + mat[k] * n2) / (n1 + n2)
                other["pixels"] = n1 + n2
                other["pixels_refined"] += mat["pixels_refined"]
                other["seconds"] += mat["seconds"]
                other["regions"] = other.get("regions", [other["region"]]) + [mat["region"]]
                break
        else:
            out.append(dict(mat))
    return out


def _scatter_rows(arr, idx, values):
    flat = arr.reshape((-1,) + arr.shape[2:])
    flat[idx] = values

