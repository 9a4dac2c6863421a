"""Cast shadows from a height map: which lights the surface itself hides from each pixel.

A pixel at height z(p) sees a distant light s = (s_x, s_y, s_z) unless some point of the surface
along the light's horizontal direction rises above the ray towards it: with d the horizontal unit
direction and t the distance along it (pixel pitches),

    horizon(p, d) = max_t atan((z(p + t d) − z(p)) / t),      elevation(s) = atan(s_z / |s_xy|),

and the light is hidden where horizon − elevation > `margin_deg` (a horizon test, as in
horizon-based ambient occlusion). The heights are an estimate (integrated from normals, which
round a wall's rim off and lower the horizon), so the margin decides the lights just above or
below a wall's edge, the soft edge of the test (pipeline._shadows.SHADOW_MARGIN_DEG: negative,
the lights up to that far above the horizon count as hidden too). The march steps every pixel up to SHORT_STEPS, then
geometrically (×STEP_GROWTH), stopping at the image's edge or the mask's (outside it nothing is
known, so nothing hides). Large images are binned first (at most HORIZON_PIXELS cells).
"""
import numpy as np

from ._integrate import integrate_least_squares

__all__ = ["horizon_excess", "hidden_lights", "heights_in_pixels", "HORIZON_PIXELS"]

HORIZON_PIXELS = 400_000   # cells at most for the heights and the march (a 12 MP scan: bins of 6x6)
# the heights' least squares by multigrid to this relative residual, not solved exactly: a horizon
# test on heights integrated from noisy normals needs no more (the alternation's two integrations at
# 0.34 M cells: the direct solve's 3-4 CPU s each)
HEIGHTS_RTOL = 1e-6
SHORT_STEPS = 12           # pixel steps before the march lengthens its steps
STEP_GROWTH = 1.12


def _steps(limit):
    """Distances (pixel pitches) the march samples, up to `limit`."""
    out, t = list(range(1, SHORT_STEPS + 1)), float(SHORT_STEPS)
    while t < limit:
        t *= STEP_GROWTH
        out.append(t)
    return np.asarray(out, np.float32)


def _bin(a, f, reduce="mean"):
    h, w = a.shape[:2]
    hc, wc = h // f, w // f
    b = a[:hc * f, :wc * f].reshape(hc, f, wc, f, *a.shape[2:])
    return b.mean(axis=(1, 3)) if reduce == "mean" else b.all(axis=(1, 3))


def heights_in_pixels(normals, mask, max_pixels=HORIZON_PIXELS):
    """(heights (h, w) float32 in the binned grid's pitches, mask (h, w) bool, bin factor f) of a
    normal map: least squares on the mask (each connected piece on its own, no walls made up
    across the mask's edges), binned by f so that at most `max_pixels` cells are solved."""
    mask = np.asarray(mask, bool)
    f = max(1, int(np.ceil(np.sqrt(mask.sum() / max_pixels))))
    n, m = (normals, mask) if f == 1 else (_bin(np.asarray(normals, np.float32), f), _bin(mask, f, "all"))
    nrm = np.linalg.norm(n, axis=-1, keepdims=True)
    m = m & (nrm[..., 0] > 0.5)
    n = np.where(m[..., None], n / np.maximum(nrm, 1e-9), 0)
    return integrate_least_squares(n, 1.0, m, rtol=HEIGHTS_RTOL), m, f


def horizon_excess(z, mask, light_dirs):
    """(m, h, w) float32: each light's horizon (degrees) less its elevation, per pixel (module
    doc); −90 where nothing rises in its direction or off the mask. z in pixel pitches."""
    from ._shadows_jit import horizon_excess_kernel
    L = np.asarray(light_dirs, np.float64)
    if L.ndim != 2 or L.shape[1] != 3:
        raise ValueError(f"light_dirs must be (m, 3) distant directions, got {L.shape}")
    h, w = z.shape
    out = np.empty((len(L), h, w), np.float32)
    horizontal = np.hypot(L[:, 0], L[:, 1])
    steps = _steps(float(np.hypot(h, w)))
    for k in range(len(L)):
        if horizontal[k] < 1e-6:          # a light on the axis: nothing hides it
            out[k] = -90.0
            continue
        # image rows run down as y runs up
        dc, dr = L[k, 0] / horizontal[k], -L[k, 1] / horizontal[k]
        elevation = np.degrees(np.arctan2(L[k, 2], horizontal[k]))
        horizon_excess_kernel(np.ascontiguousarray(z, np.float32), np.ascontiguousarray(mask), float(dr), float(dc),
                              steps, float(elevation), out[k])
    return out


def hidden_lights(normals, mask, light_dirs, margin_deg):
    """(m, H, W) bool: the lights the surface of `normals` hides from each pixel of `mask` (its
    horizon more than `margin_deg` above them), at the normals' size; and the heights' bin factor.
    The same test as `horizon_excess(...) > margin_deg`, each march stopped once it is decided."""
    from ._shadows_jit import hidden_kernel
    mask = np.asarray(mask, bool)
    L = np.asarray(light_dirs, np.float64)
    if L.ndim != 2 or L.shape[1] != 3:
        raise ValueError(f"light_dirs must be (m, 3) distant directions, got {L.shape}")
    z, m, f = heights_in_pixels(normals, mask)
    z = np.ascontiguousarray(z, np.float32)
    hc, wc = z.shape
    hidden = np.zeros((len(L), hc, wc), bool)
    horizontal = np.hypot(L[:, 0], L[:, 1])
    steps = _steps(float(np.hypot(hc, wc)))
    z_top = float(z[m].max()) if m.any() else 0.0
    m = np.ascontiguousarray(m)
    for k in range(len(L)):
        above = np.degrees(np.arctan2(L[k, 2], horizontal[k])) + margin_deg     # the horizon that hides it
        if horizontal[k] < 1e-6 or above >= 90.0:       # a light on the axis: nothing hides it
            continue
        dc, dr = L[k, 0] / horizontal[k], -L[k, 1] / horizontal[k]      # image rows run down as y runs up
        hidden_kernel(z, m, float(dr), float(dc), steps, float(np.tan(np.radians(above))), z_top, hidden[k])
    if f > 1:
        h, w = mask.shape
        hidden = np.repeat(np.repeat(hidden, f, axis=1), f, axis=2)
        hidden = np.pad(hidden, [(0, 0), (0, h - hidden.shape[1]), (0, w - hidden.shape[2])], mode="edge")
    return hidden & mask[None], f
