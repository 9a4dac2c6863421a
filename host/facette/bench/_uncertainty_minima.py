"""The minima search's figures (facette.fit._ps_li_minima) on the concave renders under the rig's 12
lights, through `facette process`:

    python -m facette.bench._uncertainty_minima [--cache DIR] [--scenes grooves/paint_0.10,...] [--off]

Per scene, on the pixels li_alternating's last call solved BRDF-aware: the minimum T its per-pixel solve
reaches from the TRUE normal (its own model); "nearer": T more than 5° nearer the truth than li's normal
before the search; "cheaper": T's robust cost (every usable light, li's scale) below that normal's; and
the share of the cheaper nearer minima the final normal sits in (< 2°). --off: the same without the
search (the neighbour starts alone). Then the search's cost gap (`Pixels.minima_gap`, the searched
pixels only) against the true error: its Spearman alone, the band's (normal.exr's uncertainty_deg) on
the same pixels, and the whole band's with the gap folded in, band × (1 + k (1 − gap)) where searched.
"""
import argparse

import numpy as np
from scipy.ndimage import binary_erosion
from scipy.stats import spearmanr

from facette.bench import concave as cc
from facette.fit import _ps_li_pixels as pp
from facette.fit._normals_li import CAST_SHADOW_RATIO, MAX_STEP, SCALE_FLOOR
from facette.fit._ps_li_minima import ITERATIONS, STEP_TOL
from facette.fit._ps_li_minima_jit import search_minima_compiled

SCENES = ("bowl/paint_0.10", "grooves/paint_0.10", "craters/paint_0.10", "cup/paint_0.10", "bowl/paint_0.05@dark",
          "grooves/paint_0.05@dark", "craters/paint_0.05@dark", "cup/paint_0.05@dark")
GAP_WEIGHTS = (0.0, 0.5, 1.0, 2.0)


def _angle(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, -1), -1, 1)))


def _truth_minima(px, cand, truth, sigma, n_i):
    """(T (n, 3): the minimum reached from the true normals, cheaper (n,) bool: its cost below that of the
    current normals' minimum, on the current solve's scale, every usable light)."""
    e, ok = px.gather(cand), px.all_ok[cand]
    common = (px.s_all, sigma, n_i, ITERATIONS)
    tail = (CAST_SHADOW_RATIO, SCALE_FLOOR, MAX_STEP, STEP_TOL)
    t_min = search_minima_compiled(e, ok, truth, np.float32([[0, 0, 1]]), *common, 0, 5.0, *tail,
                                   volume_model=px.vm)[0]
    _, here, best, _ = search_minima_compiled(e, ok, px.nrm[cand], t_min[:, None, :], *common, 1, 0.5, *tail,
                                              volume_model=px.vm)
    return t_min, best < here


def scene_figures(d, folder, search=True):
    """process() on the scene's folder with li's last call watched: a dict of the figures (module doc)."""
    seen = {}
    original = pp.Pixels.neighbour_round

    def watched(px, pix, sigma, n_i, **kw):
        cand = pix[px.refined[pix]]
        truth = d["normals"].reshape(-1, 3)[px.idx[cand]].astype(np.float32)
        t_min, cheaper = _truth_minima(px, cand, truth, sigma, n_i)
        seen.update(px=px, cand=cand, truth=truth, t_min=t_min, cheaper=cheaper, before=px.nrm[cand].copy())
        return original(px, pix, sigma, n_i, **kw)

    pp.Pixels.neighbour_round, limit = watched, pp.SEARCH_MAX_LIGHTS
    pp.SEARCH_MAX_LIGHTS = limit if search else 0
    try:
        n, _, res = cc.run(folder)
    finally:
        pp.Pixels.neighbour_round, pp.SEARCH_MAX_LIGHTS = original, limit
    px, cand = seen["px"], seen["cand"]
    final = px.nrm[cand]
    nearer = _angle(seen["t_min"], seen["truth"]) < _angle(seen["before"], seen["truth"]) - 5
    cn = nearer & seen["cheaper"]
    out = {"mean": float(cc.errors(n, d).mean()), "nearer": float(nearer.mean()),
           "cheaper_of_nearer": float(cn.sum() / max(nearer.sum(), 1)),
           "found": float((_angle(final, seen["t_min"]) < 2)[cn].mean()) if cn.any() else float("nan")}
    gap = np.full(d["mask"].size, np.nan)
    if px.minima_gap is not None:
        gap[px.idx] = px.minima_gap
    err = np.degrees(np.arccos(np.clip(np.sum(n * d["normals"], -1), -1, 1)))
    sel = binary_erosion(d["mask"], iterations=1) & np.isfinite(res.uncertainty)
    err, band, gap = err[sel], res.uncertainty[sel], gap.reshape(d["mask"].shape)[sel]
    s = np.isfinite(gap)
    if s.sum() > 2:
        out.update(gap_rho=spearmanr(-gap[s], err[s]).statistic, band_rho_searched=spearmanr(band[s], err[s]).statistic)
    for k in GAP_WEIGHTS:
        out[f"band_rho_k{k}"] = spearmanr(np.where(s, band * (1 + k * (1 - np.nan_to_num(gap, nan=1.0))), band),
                                          err).statistic
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", default="/tmp/facette-concave", help="the concave renders' cache")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--off", action="store_true", help="without the search (the neighbour starts alone)")
    args = ap.parse_args(argv)
    for name in args.scenes.split(","):
        shape, material = name.split("/")
        d = cc.scene(shape, material, "rig12", args.cache)
        folder = cc._folder(d, args.cache + "/folders", name.replace("/", "_"))
        f = scene_figures(d, folder, search=not args.off)
        print(f"{name:26s} " + "  ".join(f"{k} {v:.3f}" for k, v in f.items()), flush=True)


if __name__ == "__main__":
    main()
