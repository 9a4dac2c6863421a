"""report.html: one self-contained page (pictures embedded as PNG) describing a `process` run."""
import base64
import html
import io

import numpy as np

__all__ = ["write_report"]


def _png(fig):
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    import matplotlib.pyplot as plt
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
        title = f"{title}: {lo:.4g} to {hi:.4g} {label}".rstrip()
    else:
        rgb = np.clip(np.nan_to_num(img), 0, 1)
    # small maps are enlarged (nearest) so that they stay readable on the page
    k = max(1, int(400 // max(rgb.shape[:2])))
    rgb8 = (np.repeat(np.repeat(rgb, k, 0), k, 1) * 255 + 0.5).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(rgb8).save(buf, format="PNG")
    return title, "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _curves(filtered):
    """In-plane reflectance curves: the mean BRDF (green) of the cells within 15 deg of the
    incidence plane, averaged per ring (weighted by samples), against the signed theta_o
    (negative: the mirror side, phi_o = pi), for up to six incidence bins spread over theta_s."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    o = filtered.o
    phi = np.arctan2(o[:, 1], o[:, 0])
    cosz = np.clip(o[:, 2], -1, 1)
    ring = np.clip(np.searchsorted(filtered.edges, np.arccos(cosz), side="right") - 1, 0,
                   len(filtered.counts) - 1)
    theta_mid = np.degrees(np.arccos(cosz))
    ch = 1 if filtered.mean.shape[2] > 1 else 0
    tol = np.radians(15)
    drawn = 0
    filled = filtered.count.sum(1)
    usable = np.flatnonzero(filled >= 0.01 * max(filled.max(), 1))
    # spread over the incidences: with lights near the camera only small theta_s reach the mirror
    picks = usable[np.unique(np.linspace(0, len(usable) - 1, min(6, len(usable))).round().astype(int))] \
        if len(usable) else []
    for b in picks:
        xs, ys = [], []
        for side, sel_side in ((1, np.abs(phi) < tol), (-1, np.abs(np.abs(phi) - np.pi) < tol)):
            for j in np.unique(ring):
                sel = sel_side & (ring == j) & (filtered.count[b] > 0)
                if j == 0:
                    sel = (ring == 0) & (filtered.count[b] > 0)
                if not sel.any():
                    continue
                wts = filtered.count[b, sel]
                xs.append(side * float(theta_mid[sel].mean()))
                ys.append(float(np.sum(filtered.mean[b, sel, ch] * wts) / wts.sum()))
        if len(xs) < 2:
            continue
        order = np.argsort(xs)
        ax.plot(np.array(xs)[order], np.array(ys)[order], "o-", ms=3,
                label=f"θs ≈ {np.degrees(filtered.theta_s[b]):.1f}°")
        drawn += 1
    ax.set_xlabel("θo in the incidence plane (deg; − mirror side, + light side)")
    ax.set_ylabel("BRDF, green (1/sr with calibrated intensities)")
    ax.set_yscale("log")
    ax.set_title("Filtered reflectance (hemispherical sensor)")
    if drawn:
        ax.legend(fontsize=8)
    return "Reflectance curves", _png(fig)


def write_report(res, path):
    """Write report.html for a `ProcessResult` (maps, masks, curves, timings, options)."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    figs = []
    st = max(1, int(np.ceil(max(res.normals.shape[:2]) / 800)))   # pictures need no more
    n, mask, ps = res.normals[::st, ::st], res.mask[::st, ::st], res.ps
    figs.append(_map("Normal map ((n+1)/2 as RGB)", np.where(mask[..., None], (n + 1) / 2, 0)))
    albedo = res.albedo[::st, ::st]
    top = float(np.percentile(albedo[mask], 99)) if mask.any() else 1.0
    figs.append(_map("Albedo (scaled to the 99th percentile)", np.clip(albedo / max(top, 1e-12), 0, 1)))
    resid = np.where(mask, ps.residual[::st, ::st], np.nan)
    figs.append(_map("Least-squares relative residual (confidence: low is Lambertian)", resid,
                     cmap="magma", vmin=0,
                     vmax=max(float(np.nanpercentile(resid, 99)) if mask.any() else 1, 1e-6)))
    if ps.method.startswith("hierarchical"):
        figs.append(_map("Triplets kept", np.where(mask, ps.n_triplets[::st, ::st], np.nan),
                         cmap="viridis"))
        figs.append(_map("Lights flagged as shadow",
                         np.where(mask, ps.shadow[::st, ::st].sum(-1), np.nan), cmap="Reds",
                         label="lights"))
        figs.append(_map("Lights flagged as specular",
                         np.where(mask, ps.specular[::st, ::st].sum(-1), np.nan), cmap="Blues",
                         label="lights"))
    if res.height is not None:
        figs.append(_map("Height (mm)", np.where(mask, res.height[::st, ::st], np.nan),
                         cmap="terrain", label="mm"))
    truth = res.inputs.truth if res.inputs is not None else None
    if truth and "normals" in truth and truth["normals"].shape == res.normals.shape:
        tn = truth["normals"][::st, ::st]
        err = np.degrees(np.arccos(np.clip(np.sum(n * tn, -1), -1, 1)))
        figs.append(_map("Angular error against truth (deg)", np.where(mask, err, np.nan),
                         cmap="inferno", vmin=0, vmax=10, label="deg"))
    if res.filtered is not None:
        figs.append(_curves(res.filtered))
    rows = "".join(f"<tr><td>{html.escape(k)}</td><td>{v:.3f} s</td></tr>" for k, v in res.timings.items())
    opts = "".join(f"<tr><td>{html.escape(str(k))}</td><td>{html.escape(str(v))}</td></tr>"
                   for k, v in res.options.items())
    errs = "".join(f"<tr><td>{html.escape(k)}</td><td>{v:.3f}</td></tr>" for k, v in res.errors.items())
    info = "".join(f"<tr><td>{html.escape(str(k))}</td><td>{html.escape(str(v))}</td></tr>"
                   for k, v in (ps.info or {}).items())
    notes = "".join(f"<li>{html.escape(x)}</li>" for x in res.notes)
    brdf = f"<pre>{html.escape(str(res.brdf))}</pre>" if res.brdf is not None else "<p>not fitted</p>"
    imgs = "".join(f'<figure><img src="{src}" alt="{html.escape(t)}"><figcaption>{html.escape(t)}'
                   "</figcaption></figure>" for t, src in figs)
    src = html.escape(str(res.inputs.source)) if res.inputs is not None else ""
    page = f"""<!DOCTYPE html><html><head><meta charset="utf-8"><title>facette report</title>
<style>body{{font-family:sans-serif;margin:2em}}figure{{display:inline-block;margin:0.5em}}
td{{padding:0 1em}}img{{max-width:520px}}</style></head><body>
<h1>facette process</h1><p>Source: {src} ({res.inputs.kind if res.inputs else ''},
{res.normals.shape[1]}×{res.normals.shape[0]} px, {int(res.mask.sum())} valid pixels)</p>
<h2>Options</h2><table>{opts}</table><h2>Photometric stereo</h2><table>{info}</table>
<h2>Error against the scan's truth</h2>{('<table>' + errs + '</table>') if errs else '<p>no truth.npz</p>'}
<h2>Timings</h2><table>{rows}</table><h2>BRDF</h2>{brdf}<h2>Notes</h2><ul>{notes}</ul>
<h2>Pictures</h2>{imgs}</body></html>"""
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(page, encoding="utf-8")
    tmp.replace(path)
