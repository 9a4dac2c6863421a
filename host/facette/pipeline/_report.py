"""report.html: one self-contained page describing a `process` run (no server, no network).

Top to bottom: a summary (what was measured, how good, what was left out and why), the
relighting viewer (facette.pipeline._viewer), the BRDF fit (parameters with uncertainties,
the filtered reflectance against the fitted model per incidence, residuals per cell), the
error against the scan's truth as histograms, the maps, then options and timings.
Pictures are embedded PNGs (matplotlib); numbers are rounded for reading (`fmt`, `fmt_pm`).
"""
import base64
import html
import io
import json
import math

import numpy as np

from facette._memory import decimated, masked_values
from facette.io.atomic import write_text_atomic
from facette.fit import FitModel, cell_spread_directions, incidence_spread
from facette.capture import NO_PITCH_NOTE
from facette.pipeline._confidence import confidence_maps
from facette.pipeline._report_overlay import mask_overlay
from facette.pipeline._viewer import viewer_data, viewer_section

__all__ = ["write_report", "fmt", "fmt_pm", "fit_predictions"]

MAX_PANELS = 6   # incidence bins drawn (spread over the filled ones)


# ----------------------------------------------------------------------------- numbers

def fmt(x, digits=3):
    """A number for people: ints with thin-space thousands, floats to `digits` significant digits
    without exponent between 1e-3 and 1e6 (not six decimals: 0.000206), '–' for None or NaN."""
    if x is None or isinstance(x, str):
        return "–" if x is None else x
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return f"{int(x):,}".replace(",", "\u2009")
    x = float(x)
    if not math.isfinite(x):
        return "–"
    if x == 0:
        return "0"
    ax = abs(x)
    if ax >= 1e6 or ax < 1e-3:
        return f"{x:.{digits - 1}e}"
    if ax >= 10 ** digits:
        return f"{round(x):,}".replace(",", "\u2009")
    dec = max(0, digits - 1 - int(math.floor(math.log10(ax))))
    return f"{x:.{dec}f}"


def fmt_pm(value, sd):
    """'value ± sd' with sd to 2 significant digits and value to the same decimal place."""
    if sd is None or not np.isfinite(sd) or sd <= 0:
        return fmt(value, 4)
    dec = max(0, 1 - int(math.floor(math.log10(sd))))     # below 1e-4 an exponent, not six decimals
    return f"{value:.2e} ± {sd:.1e}" if dec > 5 else f"{value:.{dec}f} ± {sd:.{dec}f}"


def _pct(x):
    return "–" if x is None or not np.isfinite(x) else f"{100 * x:.{0 if abs(x) >= 0.1 else 1}f} %"


def _value(k, v):
    """A table cell: fractions as percent, lists element by element, dicts as 'key value; ...'
    (li_alternating's rounds, materials and levels)."""
    if isinstance(v, dict):
        return "; ".join(f"{kk} {_value(kk, vv)}" for kk, vv in v.items())
    if isinstance(v, (list, tuple, np.ndarray)):
        return ", ".join(_value(k, x) for x in v)
    if isinstance(v, (float, np.floating)) and "fraction" in str(k):
        return _pct(v)
    return fmt(v)


def _rows(d, unit=""):
    return "".join(f"<tr><td>{html.escape(str(k))}</td><td>{html.escape(_value(k, v))}{unit}</td></tr>"
                   for k, v in d.items())


# ----------------------------------------------------------------------------- pictures

def _png(fig, tight=True):
    """fig as a PNG data URI. tight=False keeps the figure's own margins: bbox_inches="tight"
    draws the figure twice, which doubles the time of the multi-panel plots."""
    import matplotlib.pyplot as plt
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight" if tight else None)
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _decimate(a, max_side=800):
    step = max(1, int(np.ceil(max(a.shape[:2]) / max_side)))
    return a[::step, ::step]


def _map(title, img, cmap=None, vmin=None, vmax=None, label=""):
    """A map as an embedded PNG, coloured with a matplotlib colormap but drawn without a
    figure (much faster); the value range goes into the caption. NaN is drawn black."""
    from matplotlib import colormaps
    from PIL import Image
    img = _decimate(np.asarray(img, dtype=np.float64))
    if img.ndim == 2:
        finite = np.isfinite(img)
        lo = float(np.min(img[finite])) if vmin is None and finite.any() else (vmin or 0.0)
        hi = float(np.max(img[finite])) if vmax is None and finite.any() else (vmax or 1.0)
        t = np.clip((img - lo) / (hi - lo if hi > lo else 1.0), 0, 1)
        rgb = colormaps[cmap or "viridis"](np.nan_to_num(t))[..., :3]
        rgb[~finite] = 0
        title = f"{title}: {fmt(lo)} to {fmt(hi)} {label}".rstrip()
    else:
        rgb = np.clip(np.nan_to_num(img), 0, 1)
    # small maps are enlarged (nearest) so that they stay readable on the page
    k = max(1, int(400 // max(rgb.shape[:2])))
    rgb8 = (np.repeat(np.repeat(rgb, k, 0), k, 1) * 255 + 0.5).astype(np.uint8)
    buf = io.BytesIO()
    # zlib level 1: an 800 px map in 0.04 s instead of 0.11, 5 % larger
    Image.fromarray(rgb8).save(buf, format="PNG", compress_level=1)
    return title, "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _plain_log_y(ax):
    """Log y axis with plain numbers ("0.2", not mathtext 2×10⁻¹, which is also 3x slower to lay out)."""
    from matplotlib.ticker import FuncFormatter, NullFormatter
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: fmt(v, 2)))
    ax.yaxis.set_minor_formatter(NullFormatter())


def _figures(figs):
    return "".join(f'<figure><img src="{src}" alt="{html.escape(t)}"><figcaption>{html.escape(t)}'
                   "</figcaption></figure>" for t, src in figs)


# ----------------------------------------------------------------------------- the fit

def fit_predictions(filtered, fit, min_count=1, spread=4):
    """The fitted model as the hemispherical sensor sees it, (B, N, C), NaN in cells with fewer
    than min_count samples: the fit's own forward model (facette.fit.FitModel, as
    fit_hemisphere_cells builds it: the lobe over spread² directions per cell and incidences per bin)."""
    b, c = np.nonzero(filtered.count >= min_count)
    pred = np.full(filtered.mean.shape, np.nan)
    if b.size:
        o_spread = cell_spread_directions(filtered.edges, filtered.counts, c, spread) if spread else None
        s_spread = incidence_spread(filtered.edges, b, spread) if spread else None
        model = FitModel(fit.model, filtered.s[b], filtered.o[c], filtered.mean.shape[2],
                         distribution=fit.distribution or "beckmann", masking=fit.masking or "smith",
                         volume=fit.volume or "quadrature", interreflection=bool(fit.interreflection),
                         o_spread=o_spread, s_spread=s_spread)
        kd = np.broadcast_to(np.asarray(fit.params["kd"], dtype=float), (filtered.mean.shape[2],))
        p = [fit.params[k] for k in model.names[:model.n_shared]] + list(kd)
        pred[b, c] = model.predict(np.asarray(p, dtype=float))
    return pred


def _incidence_picks(filtered):
    """Up to MAX_PANELS incidence bins with data, spread over θ_s."""
    filled = filtered.count.sum(1)
    usable = np.flatnonzero(filled >= 0.01 * max(filled.max(), 1))
    if not len(usable):
        return []
    return list(usable[np.unique(np.linspace(0, len(usable) - 1, min(MAX_PANELS, len(usable)))
                                 .round().astype(int))])


def _in_plane(filtered, values, b, ch, tol_deg=15):
    """Signed θ_o (deg; − on the mirror side) and the count-weighted mean of `values`[b, :, ch]
    over the cells of each ring within tol_deg of the incidence plane."""
    o = filtered.o
    phi = np.arctan2(o[:, 1], o[:, 0])
    cosz = np.clip(o[:, 2], -1, 1)
    ring = np.clip(np.searchsorted(filtered.edges, np.arccos(cosz), side="right") - 1, 0, len(filtered.counts) - 1)
    theta = np.degrees(np.arccos(cosz))
    tol = np.radians(tol_deg)
    xs, ys = [], []
    for side, near in ((1, np.abs(phi) < tol), (-1, np.abs(np.abs(phi) - np.pi) < tol)):
        for j in np.unique(ring):
            sel = ((ring == 0) if j == 0 else (near & (ring == j))) & (filtered.count[b] > 0)
            sel &= np.isfinite(values[b, :, ch])
            if j == 0 and side < 0 or not sel.any():
                continue
            w = filtered.count[b, sel]
            xs.append(side * float(theta[sel].mean()))
            ys.append(float(np.sum(values[b, sel, ch] * w) / w.sum()))
    order = np.argsort(xs)
    return np.array(xs)[order], np.array(ys)[order]


def _channel(filtered):
    return 1 if filtered.mean.shape[2] > 1 else 0


def _panels(n, size):
    """A figure of n panels, three a row (size: inches per panel); unused panels hidden."""
    import matplotlib.pyplot as plt
    cols = min(3, max(1, n))
    rows = int(np.ceil(n / cols)) or 1
    fig, axes = plt.subplots(rows, cols, figsize=(size[0] * cols, size[1] * rows), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    return fig, axes, rows


def _curves(filtered, pred, picks):
    """Per incidence: the filtered reflectance (points) and the fitted model seen through the
    same cells (line), in the incidence plane, on the same axes."""
    ch = _channel(filtered)
    fig, axes, rows = _panels(len(picks), (4.2, 3.2))
    for ax, b in zip(axes.ravel(), picks):
        x, y = _in_plane(filtered, filtered.mean, b, ch)
        ax.plot(x, y, "o", ms=3, color="C0", label="filtered data")
        ym = []
        if pred is not None:
            xm, ym = _in_plane(filtered, pred, b, ch)
            ax.plot(xm, ym, "-", color="C3", lw=1.5, label="fitted model")
        vals = np.concatenate([y, ym if pred is not None else []])
        vals = vals[np.isfinite(vals) & (vals > 0)]
        if vals.size and vals.max() > 10 * vals.min():       # a lobe: log scale
            _plain_log_y(ax)
        ax.set_title(f"θs ≈ {np.degrees(filtered.theta_s[b]):.0f}°", fontsize=10)
        ax.set_xlabel("θo in the incidence plane (deg)", fontsize=8)
        ax.tick_params(labelsize=8)
    axes[0, 0].set_ylabel("BRDF, green (1/sr)", fontsize=8)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Reflectance in the incidence plane" + (": data and fitted model" if pred is not None else "")
                 + " (− mirror side, + light side)", fontsize=10)
    fig.subplots_adjust(hspace=0.5, wspace=0.3, left=0.08, right=0.98, bottom=0.18 if rows == 1 else 0.1,
                        top=0.85 if rows == 1 else 0.91)
    return ("Filtered reflectance and fitted model per incidence" if pred is not None
            else "Filtered reflectance per incidence (no fitted model)"), _png(fig, tight=False)


def _residual_maps(filtered, pred, picks):
    """Relative residual (data − model) / model of every filled cell, per incidence, on the
    hemisphere seen from above (equal-area projection; the light comes from +x)."""
    import matplotlib.pyplot as plt
    ch = _channel(filtered)
    fig, axes, _ = _panels(len(picks), (3.6, 3.4))
    o = filtered.o
    r = np.sqrt(2) * np.sin(np.arccos(np.clip(o[:, 2], -1, 1)) / 2)    # equal-area, 1 at the horizon
    phi = np.arctan2(o[:, 1], o[:, 0])
    x, y = r * np.cos(phi), r * np.sin(phi)
    sc = None
    for ax, b in zip(axes.ravel(), picks):
        sel = (filtered.count[b] > 0) & np.isfinite(pred[b, :, ch]) & (pred[b, :, ch] > 0)
        rel = (filtered.mean[b, sel, ch] - pred[b, sel, ch]) / pred[b, sel, ch]
        sc = ax.scatter(x[sel], y[sel], c=100 * rel, s=9, cmap="RdBu_r", vmin=-50, vmax=50)
        ax.add_patch(plt.Circle((0, 0), 1, fill=False, lw=0.5, color="0.5"))
        ax.set_aspect("equal")
        ax.set_xlim(-1.05, 1.05)
        ax.set_ylim(-1.05, 1.05)
        ax.set_xticks([])
        ax.set_yticks([])
        rms = float(np.sqrt(np.mean(rel ** 2))) if rel.size else float("nan")
        ax.set_title(f"θs ≈ {np.degrees(filtered.theta_s[b]):.0f}°: {sel.sum()} cells, "
                     f"rms {_pct(rms)}", fontsize=9)
    if sc is not None:
        fig.colorbar(sc, ax=axes.ravel().tolist(), shrink=0.8, label="(data − model) / model, %")
    return ("Residual per sensor cell (hemisphere from above, light towards +x; clipped at ±50 %)",
            _png(fig, tight=False))


_PARAM_NAMES = {"kd": "K_d (substrate reflectance)", "sigma": "σ (roughness, RMS slope)",
                "n_i": "n_i (relative refractive index)"}


def _params_table(fit, truth_brdf=None, truth_kd=None):
    """Rows: parameter, value ± one standard deviation, truth (when simulated)."""
    params = getattr(fit, "params", {}) or {}
    unc = getattr(fit, "uncertainties", {}) or {}
    tparams = (truth_brdf or {}).get("params", {}) if isinstance(truth_brdf, dict) else {}
    rows = []
    for k, v in params.items():
        sd = unc.get(k)
        if isinstance(v, (list, tuple, np.ndarray)):
            sds = list(sd) if isinstance(sd, (list, tuple, np.ndarray)) else [None] * len(v)
            names = "RGB" if len(v) == 3 else [str(i) for i in range(len(v))]
            tv = truth_kd if k == "kd" else tparams.get(k)
            for i, (x, s) in enumerate(zip(v, sds)):
                t = tv[i] if isinstance(tv, (list, tuple, np.ndarray)) and len(tv) == len(v) else None
                rows.append((f"{_PARAM_NAMES.get(k, k)} {names[i]}", fmt_pm(x, s), fmt(t) if t is not None else ""))
        else:
            t = tparams.get(k)
            rows.append((_PARAM_NAMES.get(k, k), fmt_pm(v, sd), fmt(t) if isinstance(t, (int, float)) else ""))
    has_truth = any(r[2] for r in rows)
    head = "<tr><th>parameter</th><th>fitted ± 1 s.d.</th>" + ("<th>truth</th>" if has_truth else "") + "</tr>"
    body = "".join(f"<tr><td>{html.escape(a)}</td><td>{html.escape(b)}</td>"
                   + (f"<td>{html.escape(c)}</td>" if has_truth else "") + "</tr>" for a, b, c in rows)
    return f"<table>{head}{body}</table>"


def _fit_section(res, truth_brdf, truth_kd):
    fit, filtered = res.brdf, res.filtered
    if fit is None:
        why = ("not requested (--outputs without brdf)" if "brdf" not in res.options.get("outputs", ())
               else "no fit (see the notes)")
        picks = _incidence_picks(filtered) if filtered is not None else []
        figs = [_curves(filtered, None, picks)] if picks else []
        return f"<h2>BRDF fit</h2><p>{why}.</p>" + _figures(figs), None
    d = fit.to_dict() if hasattr(fit, "to_dict") else dict(fit)
    err = d.get("fit_error") or {}
    lines = [f"Model: {html.escape(str(d.get('model')))}"
             + (f" ({html.escape(str(d.get('distribution')))} facets, {html.escape(str(d.get('masking')))} masking,"
                + (" coupled diffuse part: the substrate through the interface)" if d.get("volume") == "coupled"
                   else f" volume part by {html.escape(str(d.get('volume')))})") if d.get("model") == "li" else "")
             + f"; {'converged' if d.get('success') else 'FAILED'}"
             + f" by {html.escape(str(d.get('method')))} in {fmt(d.get('time_s'), 2)} s.",
             f"Fitted to {fmt(err.get('n_samples'))} sensor cells × {fmt(err.get('n_channels'))} channels: "
             f"RMS error {fmt(err.get('rms'))} 1/sr, {_pct(err.get('relative_rms'))} of the data's RMS."]
    if d.get("verdict"):
        lines.insert(0, f"<b>Verdict: {html.escape(str(d['verdict']))}</b> (models tried: " + ", ".join(
            f"{html.escape(str(t['model']))} {_pct(t.get('relative_rms'))} of the data's RMS"
            for t in d.get("models_tried") or []) + ").")
    if d.get("message") and d.get("message") != "converged":
        lines.append("Fit notes: " + html.escape(str(d["message"])))
    for s in d.get("selection") or []:
        lines.append("Model choice: " + html.escape(str(s)))
    note = ("Uncertainties: one s.d. from the Jacobian at the optimum, covariance = s² (JᵀJ)⁻¹, s² the weighted "
            "residual variance (facette.fit), for these normals: lower bounds, as the model may misfit, residuals "
            "correlate and the normals err (a rendered paint sphere: σ ± 0.0001 from one run, 0.051–0.056 "
            "over five draws of photometric stereo's fit pixels).")
    truth_note = ""
    if isinstance(truth_brdf, dict) and truth_brdf.get("model") and truth_brdf.get("model") != d.get("model"):
        truth_note = (f"<p>The simulated material is a {html.escape(str(truth_brdf['model']))} BRDF, not "
                      f"{html.escape(str(d.get('model')))}: σ and n_i are comparable in meaning, not equal by "
                      "construction. Truth K_d is the median of the simulated albedo over the material.</p>")
    body = (f"<h2>BRDF fit</h2><p>{'<br>'.join(lines)}</p>{_params_table(fit, truth_brdf, truth_kd)}"
            f"<p class='small'>{note}</p>{truth_note}")
    figs = []
    pred = None
    if filtered is not None and getattr(fit, "success", True) and getattr(fit, "params", None):
        try:
            pred = fit_predictions(filtered, fit)
        except (ValueError, TypeError, KeyError) as e:    # a model we cannot evaluate: say so
            body += f"<p>The model could not be evaluated for the plots: {html.escape(str(e))}</p>"
        picks = _incidence_picks(filtered)
        if picks:
            figs.append(_curves(filtered, pred, picks))
            if pred is not None:
                figs.append(_residual_maps(filtered, pred, picks))
                body += _residual_table(filtered, pred)
    elif filtered is not None:
        picks = _incidence_picks(filtered)
        if picks:
            figs.append(_curves(filtered, None, picks))
    return body + _figures(figs), pred


def _residual_table(filtered, pred):
    """Relative RMS residual per incidence bin (all filled cells, all channels)."""
    rows = []
    for b in range(filtered.mean.shape[0]):
        sel = (filtered.count[b] > 0) & np.all(np.isfinite(pred[b]), -1) & np.all(pred[b] > 0, -1)
        if not sel.any():
            continue
        rel = (filtered.mean[b, sel] - pred[b, sel]) / pred[b, sel]
        rows.append(f"<tr><td>{np.degrees(filtered.theta_s[b]):.0f}°</td><td>{fmt(int(sel.sum()))}</td>"
                    f"<td>{fmt(int(filtered.count[b, sel].sum()))}</td>"
                    f"<td>{_pct(float(np.sqrt(np.mean(rel ** 2))))}</td>"
                    f"<td>{_pct(float(np.median(rel)))}</td></tr>")
    if not rows:
        return ""
    return ("<details><summary>Residual per incidence bin</summary><table><tr><th>θs</th><th>cells</th>"
            "<th>samples</th><th>rms (data − model)/model</th><th>median</th></tr>"
            + "".join(rows) + "</table></details>")


# ----------------------------------------------------------------------------- truth

def _truth_kd(truth, mask):
    alb = truth.get("albedo") if truth else None
    if alb is None or alb.shape[:2] != mask.shape or not mask.any() or not np.any(alb[mask]):
        return None
    return [float(np.median(alb[..., c][mask])) for c in range(alb.shape[-1])]


def _truth_brdf(truth):
    if not truth or "brdf" not in truth:
        return None
    try:
        return json.loads(str(truth["brdf"]))
    except ValueError:
        return None


def _truth_section(res, kd_map, kd_mask):
    """Histograms of the error against truth.npz: normals (deg), heights (mm), the K_d map (%).
    kd_map : (map, step) of the viewer: the map on every step-th pixel (the viewer's preview
    size), compared with the truth's albedo on the same pixels; or None."""
    kd_map, kd_step = kd_map if kd_map is not None else (None, 1)
    import matplotlib.pyplot as plt
    truth = res.inputs.truth if res.inputs is not None else None
    if not truth or "normals" not in truth or truth["normals"].shape != res.normals.shape:
        return "<h2>Error against truth</h2><p>This scan has no truth (truth.npz comes with simulated scans).</p>"
    sel = res.mask & truth.get("mask", np.ones(res.mask.shape, bool)).astype(bool)
    panels = []
    dot = np.clip(np.sum(res.normals[sel] * truth["normals"][sel], -1), -1, 1)
    err = np.degrees(np.arccos(dot))
    panels.append(("normal angular error (deg)", err, None))
    if res.height is not None and "height_mm" in truth:
        dh = res.height[sel] - truth["height_mm"][sel]
        panels.append(("height error, mean removed (mm)", dh - dh.mean(), None))
    alb = truth.get("albedo")
    alb = None if alb is None else alb[::kd_step, ::kd_step]
    if kd_map is not None and alb is not None and alb.shape == kd_map.shape and np.any(alb[kd_mask]):
        t = alb[kd_mask][:, 1]
        ok = t > 0
        name = "K_d map relative error, green (%)" + (f", 1 pixel in {kd_step} per side (the viewer's)" if kd_step > 1 else "")
        panels.append((name, 100 * (kd_map[kd_mask][:, 1][ok] - t[ok]) / t[ok], None))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3), squeeze=False)
    rows = []
    for ax, (name, v, _) in zip(axes[0], panels):
        v = v[np.isfinite(v)]
        if not v.size:
            continue
        hi = np.percentile(np.abs(v), 99.5)
        ax.hist(np.clip(v, -hi if v.min() < 0 else 0, hi), bins=50, color="C0")
        ax.set_xlabel(name, fontsize=8)
        ax.tick_params(labelsize=8)
        _plain_log_y(ax)
        absv = np.abs(v)
        rows.append(f"<tr><td>{html.escape(name)}</td><td>{fmt(float(np.median(absv)))}</td>"
                    f"<td>{fmt(float(np.percentile(absv, 95)))}</td><td>{fmt(float(np.sqrt(np.mean(v ** 2))))}</td>"
                    f"<td>{fmt(int(v.size))}</td></tr>")
    axes[0, 0].set_ylabel("pixels", fontsize=8)
    fig.subplots_adjust(wspace=0.25, left=0.06, right=0.98, bottom=0.18, top=0.95)
    table = ("<table><tr><th>quantity</th><th>median |error|</th><th>95th percentile |error|</th>"
             "<th>rms</th><th>pixels</th></tr>" + "".join(rows) + "</table>")
    return ("<h2>Error against truth</h2>" + table
            + _figures([("Error against the scan's truth (histograms, log counts)", _png(fig, tight=False))]))


def _height_unit(res):
    """"mm", or "px" for a DiLiGenT folder processed without a pixel pitch (heights in pixels)."""
    inp = res.inputs
    if inp is not None and inp.kind == "diligent" and NO_PITCH_NOTE in inp.notes:
        return "px"
    return "mm"


# ----------------------------------------------------------------------------- summary

def _summary(res, viewer_note):
    inp, ps = res.inputs, res.ps
    h, w = res.normals.shape[:2]
    m = len(inp.light_dirs) if inp is not None and getattr(inp, "light_dirs", None) is not None else None
    valid, seen = int(res.mask.sum()), res.mask if res.filled is None else res.mask & ~res.filled   # seen: measured
    material = int((seen & inp.sample_mask()).sum()) if inp is not None else valid
    measured = (f"{fmt(m)} lights on {fmt(w)} × {fmt(h)} pixels"
                f" ({html.escape(str(inp.kind)) if inp else ''} {html.escape(str(inp.source)) if inp else ''}); "
                f"a normal on {fmt(valid)} pixels ({_pct(valid / max(h * w, 1))}), "
                f"reflectance samples from {fmt(material)} pixels of the material.")
    if res.filtered is not None:
        cells = int((res.filtered.count > 0).sum())
        bins = int((res.filtered.count.sum(1) > 0).sum())
        measured += (f" The hemispherical sensor ({fmt(res.options.get('theta0_deg'))}° cells) filled "
                     f"{fmt(cells)} cells in {fmt(bins)} incidence bins.")
    good = []
    if res.errors:
        e = res.errors
        if "normal_median_deg" in e:
            good.append(f"normals within {fmt(e['normal_median_deg'], 2)}° of the truth (median), "
                        f"{fmt(e['normal_p95_deg'], 2)}° at the 95th percentile")
        if "height_rms_mm" in e:
            good.append(f"heights within {fmt(e['height_rms_mm'], 2)} mm RMS")
    if ps is not None and valid:
        residual = float(np.median(masked_values(ps.residual, seen), overwrite_input=True))  # by bands, no copy
        good.append(f"photometric-stereo residual {_pct(residual)} (median; "
                    "0 is a perfect Lambertian fit)")
    fit = res.brdf
    if fit is not None and getattr(fit, "params", None):
        p, u = fit.params, fit.uncertainties or {}
        parts = [f"{k} = {fmt_pm(p[k], u.get(k))}" for k in ("sigma", "n_i") if k in p]
        if "kd" in p:
            parts.append("K_d = " + ", ".join(fmt(x) for x in p["kd"]))
        good.append(f"BRDF {fit.model} ({'; '.join(parts)}), fitted to "
                    f"{_pct((fit.error or {}).get('relative_rms'))} relative RMS"
                    + ("" if fit.success else " — the fit FAILED"))
    left = []
    if inp is not None:
        lost = int((inp.mask & ~res.mask).sum())
        if lost:
            left.append(f"{fmt(lost)} pixels inside the mask got no normal (too few usable lights)")
        if res.filled is not None:
            left.append(f"{fmt(int(res.filled.sum()))} pixels had no light above the noise: their normals are "
                        "interpolated from the measured ones around them (grey in mask.png)")
        bg = int((res.mask & ~inp.sample_mask()).sum())
        if bg:
            left.append(f"{fmt(bg)} pixels outside the material (dark background) are left out of the "
                        "BRDF fit; they keep their normals and heights")
    if ps is not None and ps.shadow is not None and ps.shadow.size and valid:
        sh = float(ps.shadow[seen].mean())
        if sh > 0:
            left.append(f"{_pct(sh)} of the pixel-light pairs were flagged as shadow and left out of the "
                        "reflectance samples")
    if ps is not None and ps.info and "skipped_fraction" in ps.info:
        left.append(f"least squares already explained {_pct(ps.info['skipped_fraction'])} of the pixels, "
                    "so the hierarchical search ran on the rest only")
    if fit is not None and getattr(fit, "message", "converged") not in ("converged", ""):
        left.append("fit: " + fit.message)
    if viewer_note:
        left.append(viewer_note)
    def li(xs):
        return "".join(f"<li>{html.escape(x)}</li>" for x in xs)
    notes = f"<p><b>Notes:</b></p><ul>{li(res.notes)}</ul>" if res.notes else ""
    return (f"<section class='summary'><h2>Summary</h2><p><b>Measured:</b> {measured}</p>"
            f"<p><b>How good:</b></p><ul>{li(good) or '<li>no figure of merit (no truth, no fit)</li>'}</ul>"
            f"<p><b>Left out, and why:</b></p><ul>{li(left) or '<li>nothing</li>'}</ul>{notes}</section>")


# ----------------------------------------------------------------------------- the page

def _viewer(res):
    """(html, kd_map, kd_mask, note): the relighting viewer, or why there is none."""
    if res.brdf is None and res.relight_model is None:      # process's "relight": the viewer draws it
        return "", None, None, "relighting viewer: no BRDF was fitted (output brdf not requested or no data)"
    inp = res.inputs
    try:
        data, arrays = viewer_data(
            res.normals, res.mask, res.brdf, albedo=res.albedo, kd_map=getattr(res, "kd_map", None),
            height=res.height, pitch_mm=inp.pixel_pitch_mm if inp is not None else 1.0,
            material_mask=inp.sample_mask() if inp is not None else None, relight_model=res.relight_model)
    except ValueError as e:
        return "", None, None, f"relighting viewer: {e}"
    kd_map = arrays["kd_map"]          # at the viewer's size (every `decimation`-th pixel)
    note = None
    if getattr(res.brdf, "interreflection", False):
        note = ("relighting viewer: the fit's V-cavity inter-reflection term is left out of the viewer "
                "(it depends on K_d² per pixel; the single-bounce model is drawn)")
    return viewer_section(data), (kd_map, data["decimation"]), arrays["mask"], note


def report_fit_section(res):
    """The report's BRDF section (html: parameters, uncertainties, the fit against the data,
    residuals): it needs only the fit, the filtered reflectance and the truth, so `process`
    draws it as soon as the fit is done, while the other stages still run."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    truth = res.inputs.truth if res.inputs is not None else None
    truth_kd = _truth_kd(truth, res.mask & res.inputs.sample_mask()) if res.inputs is not None else None
    return _fit_section(res, _truth_brdf(truth), truth_kd)[0]


def report_pictures(res):
    """The report's drawn parts: {"viewer": (html, note), "truth": the truth section's html, "figs": the
    maps [(title, png)]}. They need the maps, the heights, the relighting model and the BRDF fit, not
    the notes, the checks against truth or the timings: `process` draws them on a worker as soon as
    those stages are done, while the relighting files are still fitted, and `write_report` assembles
    the page at the end."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    viewer_html, kd_map, kd_mask, viewer_note = _viewer(res)
    truth = res.inputs.truth if res.inputs is not None else None
    figs = []
    st = max(1, int(np.ceil(max(res.normals.shape[:2]) / 800)))   # pictures need no more
    n, mask, ps = decimated(res.normals, st), res.mask[::st, ::st], res.ps    # disk maps: by bands
    dim = 1.0 if res.filled is None else np.where(res.filled[::st, ::st, None], 0.5, 1.0)   # interpolated: dimmed
    figs.append(_map("Normal map ((n+1)/2 as RGB" + ("" if res.filled is None else "; interpolated pixels at half "
                     "brightness") + ")", np.where(mask[..., None], (n + 1) / 2 * dim, 0)))
    albedo = decimated(res.albedo, st)
    top = float(np.percentile(albedo[mask], 99)) if mask.any() else 1.0
    figs.append(_map("Albedo (scaled to the 99th percentile)", np.clip(albedo / max(top, 1e-12), 0, 1)))
    for args, kwargs in confidence_maps(res, st, mask, np.where(mask, decimated(ps.residual, st), np.nan)):
        figs.append(_map(*args, **kwargs))
    if ps.method.startswith("hierarchical"):
        figs.append(_map("Triplets kept", np.where(mask, decimated(ps.n_triplets, st), np.nan),
                         cmap="viridis"))
        figs.append(_map("Lights flagged as shadow",
                         np.where(mask, ps.shadow[::st, ::st].sum(-1), np.nan), cmap="Reds",
                         label="lights"))
        figs.append(_map("Lights flagged as specular",
                         np.where(mask, ps.specular[::st, ::st].sum(-1), np.nan), cmap="Blues",
                         label="lights"))
    overlay = mask_overlay(res, st)
    if overlay is not None:
        figs.append(_map(*overlay))
    if res.height is not None:
        unit = _height_unit(res)
        figs.append(_map(f"Height ({unit})", np.where(mask, res.height[::st, ::st], np.nan),
                         cmap="terrain", label=unit))
    if truth and "normals" in truth and truth["normals"].shape == res.normals.shape:
        tn = truth["normals"][::st, ::st]
        err = np.degrees(np.arccos(np.clip(np.sum(n * tn, -1), -1, 1)))
        figs.append(_map("Angular error against truth (deg)", np.where(mask, err, np.nan),
                         cmap="inferno", vmin=0, vmax=10, label="deg"))
    return {"viewer": (viewer_html, viewer_note), "truth": _truth_section(res, kd_map, kd_mask), "figs": figs}


def write_report(res, path, fit_html=None, pictures=None):
    """Write report.html for a `ProcessResult`: summary, relighting viewer, BRDF fit with
    uncertainties and residuals, error against truth, maps, options, timings.
    fit_html : `report_fit_section(res)` when already drawn; pictures : `report_pictures(res)` when
    already drawn (else both drawn here)."""
    if fit_html is None:
        fit_html = report_fit_section(res)
    pictures = report_pictures(res) if pictures is None else pictures
    (viewer_html, viewer_note), figs, ps = pictures["viewer"], pictures["figs"], res.ps
    timings = "".join(f"<tr><td>{html.escape(k)}</td><td>{fmt(v, 2)} s</td></tr>" for k, v in res.timings.items())
    opts = _rows({k: (", ".join(v) if isinstance(v, list) else v) for k, v in res.options.items()})
    info = _rows(ps.info or {})
    src = html.escape(str(res.inputs.source)) if res.inputs is not None else ""
    page = f"""<!DOCTYPE html><html><head><meta charset="utf-8"><title>facette report: {src}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:1400px}}figure{{display:inline-block;margin:0.5em;vertical-align:top}}
td,th{{padding:0 1em;text-align:left}}img{{max-width:100%}}.summary{{background:#f3f3f3;padding:0.5em 1.5em;border-radius:6px}}
.small{{font-size:90%;color:#444}}</style></head><body>
<h1>facette process: {src}</h1>
{_summary(res, viewer_note)}
{viewer_html}
{fit_html}
{pictures["truth"]}
<h2>Maps</h2>{_figures(figs)}
<h2>Photometric stereo</h2><table>{info}</table>
<h2>Options</h2><table>{opts}</table>
<h2>Timings</h2><table>{timings}</table>
</body></html>"""
    write_text_atomic(path, page)
