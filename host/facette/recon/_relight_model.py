"""A relighting model from physics first, then a small residual: `fit_relight_model`.

Per pixel p, channel c and distant light l (unit vector towards the light, camera frame),
in the photographs' linear unit scaled to their white (1 = display white):

    phys(p, l) = ρ_c(p) max(n·l, 0) V(p, l) + s_c(p) max(n·h, 0)^k [n·l > 0] V(p, l) + a_c(p) max(l_z, 0)

n the pixel's normal, h the half vector of l and the camera (+z), V the cast-shadow visibility
from the integrated heights (soft at the edge; 1 without heights; kept only where they
predict the fitted lights left out better, `fit_relight_model`'s shadows="auto"), k one Blinn–Phong exponent per
capture (the one of `SHININESS` the fitted photographs fit best), a the light the surface
gathers from the room and from itself, taken proportional to the irradiance of the object's
plane (max(l_z, 0)). ρ, s, a ≥ 0 per pixel and channel (non-negative least squares, the
clipped values left out): the physical part is never negative.

What it misses (inter-reflections it does not model, the BRDF's other lobes, the normals'
errors) is kept as a residual in display values (sRGB-encoded): the fitted photographs' minus
phys's, compressed to `n_planes` planes per pixel (principal components over the lights,
as Relight's RBF basis does with the pixels themselves; as many as the lights, at most 16), each
plane's light function interpolated by kernel ridge regression over the lights: a Gaussian of
the lights' (x, y) distance plus a share of the HSH order-2 kernel (a smooth trend over the
dome). The width, the share and the ridge, and whether a residual is kept at all, are chosen by
the exact leave-one-light-out error over every pixel of the fitted photographs alone. The
residual fades to 0 away from the captured lights (at a raking light no dome photographed,
phys alone is shown).

    display(p, l) = clip(srgb(phys(p, l)) + Σ_j C_j(p) e_j(l), 0, 1)
"""
import zipfile
from dataclasses import dataclass, field, replace

import numpy as np

from facette._memory import release
from facette.errors import BadInputError
from facette.io.atomic import atomic_path

from ._rti import hsh_basis, srgb_decode, srgb_encode

__all__ = ["RelightModel", "SHININESS", "cast_shadow", "physical_basis",
           "save_relight_model", "load_relight_model", "default_planes"]

SHININESS = (8.0, 32.0, 128.0)       # Blinn–Phong exponents tried (lobes of ~20°, 10°, 5°)
SATURATED = 254.0 / 255.0            # display values at or above this are clipped: not fitted
RBF_WIDTHS = (0.5, 1.0, 2.0, 4.0, 8.0)   # Gaussian widths tried, in median spacings of the lights
HSH_MIX = (0.0, 0.1, 1.0)            # weights of the HSH order-2 kernel tried beside the Gaussian
RBF_SMOOTHING = (1e-3, 1e-2, 1e-1, 1.0)  # ridges tried, relative to the kernel's mean diagonal
MIN_PREDICTED = 0.01                 # a residual is kept if it predicts this share of itself (left out)
MAX_PLANES = 48                      # residual planes kept at most (the report's viewer draws the first 16)
PLANES_BYTES = 1 << 29               # the planes' memory at most (float16): fewer planes on large images
AMBIENT_PRIOR = 0.05                 # relative ridge on the gathered-light term (see `_nnls3`)
BLOCK_VALUES = 1 << 21              # pixel-light pairs per block of the fit (~25 MB per array, ~0.25 GB in all)
SHADOW_SOFTNESS = 1.0                # height (px) over which a cast shadow's edge goes from 1 to 0


@dataclass
class RelightModel:
    """A fitted model (see the module's docstring); arrays (H, W, ...), float32.

    normals (H, W, 3); mask (H, W) bool; rho, spec, amb (H, W, 3); shininess k; heights (H, W)
    in pixels or None; planes (H, W, 3, K) residual coefficients; centres (m, 2) the fitted
    lights' (x, y); weights (m, K) and epsilon: the Gaussian RBF of the planes' light functions,
    trend (4, K) or None: their HSH order-2 part (weights None: no residual)."""
    normals: np.ndarray
    mask: np.ndarray
    rho: np.ndarray
    spec: np.ndarray
    amb: np.ndarray
    shininess: float
    heights: np.ndarray = None
    planes: np.ndarray = None
    centres: np.ndarray = None
    weights: np.ndarray = None
    epsilon: float = 1.0
    white: float = 1.0
    softness: float = SHADOW_SOFTNESS
    spacing: float = np.inf
    reach: float = 1.0
    notes: list = field(default_factory=list)
    trend: np.ndarray = None
    loo_error: float = None

    def decimated(self, st):
        """The model at every st-th pixel (heights in the decimated grid's pixels)."""
        if st == 1:
            return self
        cut = (slice(None, None, st), slice(None, None, st))
        return RelightModel(self.normals[cut], self.mask[cut], self.rho[cut], self.spec[cut], self.amb[cut],
                            self.shininess, None if self.heights is None else self.heights[cut] / np.float32(st),
                            None if self.planes is None else self.planes[cut], self.centres, self.weights,
                            self.epsilon, self.white, self.softness / st, self.spacing, self.reach,
                            list(self.notes), self.trend)

    def first_planes(self, k):
        """The model with the residual's first k planes (its k largest principal components):
        the best k-plane residual at the fitted lights."""
        if self.weights is None or self.planes.shape[-1] <= k:
            return self
        return replace(self, planes=self.planes[..., :k], weights=self.weights[:, :k],
                       trend=None if self.trend is None else self.trend[:, :k], notes=list(self.notes))

    def light_functions(self, light):
        """The residual planes' weights e_j(l) (K,) under one light (0 without a residual).
        The residual is known near the captured lights only: beyond twice their median spacing
        from the nearest one, or lower than the lowest of them (|l_xy| above their largest,
        `reach`), it fades out (a Gaussian of that spacing), leaving the physics."""
        if self.weights is None:
            return np.zeros(0)
        light = np.asarray(light, float)
        d = np.linalg.norm(self.centres - light[:2], axis=1)
        beyond = max(float(d.min()) - 2 * self.spacing, float(np.hypot(light[0], light[1])) - self.reach, 0.0)
        fade = np.exp(-(beyond / self.spacing) ** 2)
        e = np.exp(-(self.epsilon * d) ** 2) @ self.weights
        if self.trend is not None:
            e = e + hsh_basis(light / np.linalg.norm(light), 2) @ self.trend
        return fade * e

    def physical(self, light):
        """phys (H, W, 3) under one light, linear (1 = display white), ≥ 0."""
        light = np.asarray(light, float) / np.linalg.norm(light)
        vis = None if self.heights is None else cast_shadow(self.heights, light, self.softness)
        b = physical_basis(self.normals, light[None], self.shininess, vis if vis is None else vis[None])
        out = (self.rho * b[0, ..., 0:1] + self.spec * b[0, ..., 1:2] + self.amb * b[0, ..., 2:3])
        return np.where(self.mask[..., None], out, 0.0)

    def display_unfloored(self, light):
        """srgb(phys) + residual (H, W, 3) before the residual's floor (see `display_raw`)."""
        out = srgb_encode(np.clip(self.physical(light), 0, 1))
        e = self.light_functions(light)
        if e.size:
            out = out + self.planes @ e.astype(np.float32)
        return np.where(self.mask[..., None], out, 0.0)

    def display_raw(self, light):
        """The model's display values (H, W, 3) before a viewer's clip at white: the residual
        darkens a pixel at most to black (it corrects the light the physics predicts; it is no
        light of its own), so the values are never negative."""
        return np.maximum(self.display_unfloored(light), 0.0)

    def display(self, light):
        """Display values (H, W, 3) in [0, 1] under one light (sRGB-encoded, 1 = white)."""
        return np.clip(self.display_raw(light), 0.0, 1.0)

    def relight(self, light):
        """Linear values (H, W, 3) under one light, in the fitted photographs' unit."""
        return self.white * srgb_decode(self.display(light))


def physical_basis(normals, lights, shininess, visibility=None):
    """The three terms (m, ..., 3): max(n·l,0) V, the lobe max(n·h,0)^k [n·l>0] V, max(l_z,0).
    normals (..., 3); lights (m, 3) unit; visibility (m, ...) in [0, 1] or None."""
    n = np.asarray(normals, np.float32)
    lights = np.asarray(lights, np.float32)
    ndl = np.einsum("...c,mc->m...", n, lights)
    half = lights + np.array([0, 0, 1], np.float32)
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    ndh = np.clip(np.einsum("...c,mc->m...", n, half), 0, 1)
    lit = ndl > 0
    diff = np.where(lit, ndl, 0)
    lobe = np.where(lit, ndh ** np.float32(shininess), 0)
    if visibility is not None:
        diff, lobe = diff * visibility, lobe * visibility
    amb = np.broadcast_to(np.clip(lights[:, 2], 0, None).reshape((-1,) + (1,) * (ndl.ndim - 1)), ndl.shape)
    return np.stack([diff, lobe, amb], axis=-1).astype(np.float32)


def cast_shadow(heights, light, softness=SHADOW_SOFTNESS, max_steps=64, max_pixels=1 << 20):
    """Visibility (H, W) in [0, 1] of a distant light over a height map (pixels; NaN = no
    surface): 1 where no height along the light's azimuth rises above the ray to the light,
    falling to 0 as a height rises `softness` pixels above that ray. Marched one pixel at a time (row 0 at the top,
    y up), up to `max_steps`; a light within 5° of the axis casts no shadow. A map above
    `max_pixels` is marched every s-th pixel (its heights divided by s) and the result repeated."""
    h = np.asarray(heights, np.float32)
    st = int(np.ceil(np.sqrt(h.size / max_pixels)))
    if st > 1:
        small = cast_shadow(h[::st, ::st] / np.float32(st), light, softness / st, max_steps, max_pixels)
        return np.repeat(np.repeat(small, st, axis=0), st, axis=1)[:h.shape[0], :h.shape[1]]
    light = np.asarray(light, float)
    horiz = float(np.hypot(light[0], light[1]))
    vis = np.ones(h.shape, np.float32)
    if horiz < np.sin(np.radians(5.0)):
        return vis
    rise = light[2] / horiz                      # height gained per pixel towards the light
    dx, dy = light[0] / horiz, -light[1] / horiz  # image columns right, rows down
    low = np.float32(-1e30)                      # no surface: never above a ray (finite: no inf - inf)
    hh = np.where(np.isfinite(h), h, low)
    over = np.full(h.shape, -np.inf, np.float32)
    for t in range(1, min(max_steps, max(h.shape)) + 1):
        _march_step(hh, over, t * dy, t * dx, np.float32(t * rise), low)
    vis = np.clip(1.0 - over / softness, 0, 1).astype(np.float32)     # 1 wherever the ray clears
    return np.where(np.isfinite(h), vis, 1.0).astype(np.float32)


def _march_step(hh, over, oy, ox, drop, low):
    """over = max(over, hh at (row + oy, col + ox) rounded half to even − hh − drop), in place;
    off the image: `low`. Rows are integers, so round(row + oy) = row + round(oy) unless oy is
    (nearly) a half (round half to even then depends on the row): a shifted slice, else an index
    per pixel (the viewer's shader rounds the same way)."""
    h, w = hh.shape
    if abs(abs(oy) % 1 - 0.5) > 1e-6 and abs(abs(ox) % 1 - 0.5) > 1e-6:     # (row + oy can round to a half)
        r, c = int(np.rint(oy)), int(np.rint(ox))
        rs, cs = slice(max(0, -r), min(h, h - r)), slice(max(0, -c), min(w, w - c))
        if rs.start < rs.stop and cs.start < cs.stop:
            shifted = hh[rs.start + r:rs.stop + r, cs.start + c:cs.stop + c]
            np.maximum(over[rs, cs], shifted - hh[rs, cs] - drop, out=over[rs, cs])
        return
    rows, cols = np.indices(hh.shape)
    r, c = np.rint(rows + oy).astype(int), np.rint(cols + ox).astype(int)
    ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
    other = np.where(ok, hh[np.clip(r, 0, h - 1), np.clip(c, 0, w - 1)], low)
    np.maximum(over, other - hh - drop, out=over)


DARK_FLOOR = 0.01       # linear value below which the display weight stops growing (display 0.1)


def display_weight(lin):
    """(d srgb / d x)² at max(lin, DARK_FLOOR), relative to its value at 1."""
    x = np.maximum(np.asarray(lin, np.float32), DARK_FLOOR)
    return x ** np.float32(-2 * (1 - 1 / 2.4))


_SUBSETS = [s for s in ((0, 1, 2), (0, 1), (0, 2), (1, 2), (0,), (1,), (2,))]


def _normal_equations(basis, values, weights, compiled=True):
    """(gram (N, 3, 3), rhs (N, 3, C)) float64 of weighted least squares per pixel: the float32
    products summed over the lights in float64 (one product at a time: 3x faster than an einsum
    in float64, the same to 2e-8). float32 inputs (the fits'): in one compiled pass
    (`_relight_jit.normal_equations`, the same bits; compiled=False: numpy's reductions)."""
    npx, nc = basis.shape[1], values.shape[-1]
    gram, rhs = np.empty((npx, 3, 3)), np.empty((npx, 3, nc))
    if compiled and basis.dtype == values.dtype == weights.dtype == np.float32 and len(basis):
        from facette.recon._relight_jit import normal_equations     # numba loads only when this runs
        normal_equations(basis, values, weights, gram, rhs)
        return gram, rhs
    wb = basis * weights[..., None]
    for j in range(3):
        for k in range(j, 3):
            gram[:, j, k] = gram[:, k, j] = np.add.reduce(wb[..., j] * basis[..., k], axis=0, dtype=np.float64)
        for c in range(nc):
            rhs[:, j, c] = np.add.reduce(wb[..., j] * values[..., c], axis=0, dtype=np.float64)
    return gram, rhs


def _nnls3(basis, values, weights, terms):
    """Per pixel and channel, the non-negative least-squares coefficients (N, 3, 3) of the
    three basis terms (m, N, 3) for values (m, N, 3) with weights (m, N), the terms not in
    `terms` held at 0: every subset solved in closed form, the best feasible kept. Where the
    solution with every term is feasible it is the best (no subset decreases the error more):
    the subsets are solved for the other pixels only."""
    npx, nc = basis.shape[1], values.shape[-1]
    gram, rhs = _normal_equations(basis, values, weights)
    ridge = 1e-9 * (np.trace(gram, axis1=1, axis2=2)[:, None] + 1e-12)
    # a prior towards no gathered light: on a face the lights all see alike (n·l ∝ l_z) the
    # diffuse and the room's terms are one, and the diffuse is the one that casts shadows
    gram[:, 2, 2] *= 1.0 + AMBIENT_PRIOR
    best = np.zeros((npx, 3, nc))
    best_gain = np.zeros((npx, nc))         # the fit's decrease of Σ w y², all-zero = 0
    px = np.arange(npx)                     # the pixels still solved
    for sub in _SUBSETS:
        if not set(sub) <= set(terms):
            continue
        idx = np.array(sub)
        whole = len(px) == npx                  # every pixel still solved: no copies of them
        g = (gram if len(idx) == 3 else gram[:, idx][:, :, idx]) if whole else gram[np.ix_(px, idx, idx)]
        g = g + (ridge if whole else ridge[px])[:, :, None] * np.eye(len(idx))
        b = (rhs if len(idx) == 3 else rhs[:, idx]) if whole else rhs[np.ix_(px, idx)]
        x = np.linalg.solve(g, b)                                           # (n, s, C)
        gain = np.einsum("nsc,nsc->nc", x, b)                               # x·b at the optimum
        ok = np.all(x >= 0, axis=1) & (gain > best_gain[px])
        for c in range(nc):
            sel = ok[:, c]
            full = np.zeros((int(sel.sum()), 3))
            full[:, idx] = x[sel, :, c]
            best[px[sel], :, c] = full
            best_gain[px[sel], c] = gain[sel, c]
        if len(sub) == len(terms):          # every term: feasible = done
            px = px[~np.all(ok, axis=1)]
            if not px.size:
                break
    return best


def _predict(basis, x):
    """phys (m, N, C) of the basis (m, N, 3) and coefficients x (N, 3, C), float32 (a batched
    product: 7x faster than an einsum)."""
    return np.matmul(basis.transpose(1, 0, 2), np.asarray(x, np.float32)).transpose(1, 0, 2)


def _fit_block(y, shown, b, terms):
    """Coefficients (N, 3, C) of one block: values y (m, N, C) linear, shown (m, N, C) display,
    basis b (m, N, 3). Least squares in display values, linearised: a first fit in linear
    values, then each value weighted by the square of the sRGB curve's slope at the first fit's
    prediction (dark values count as much as a viewer shows them; the prediction's, not the
    photograph's, so that a cast shadow the model does not know does not drag a pixel's
    reflectance down). Clipped values are left out."""
    ok = np.all(shown < SATURATED, axis=-1).astype(np.float32)
    pred = _predict(b, _nnls3(b, y, ok, terms))
    return _nnls3(b, y, ok * display_weight(pred.mean(axis=-1)), terms)


def _kernel(a, b, eps, mix):
    """The residual's kernel between unit lights a (p, 3) and b (q, 3): a Gaussian of their (x, y)
    distance, exp(-(eps d)²), plus `mix` × the HSH order-2 kernel h(a)·h(b) (a smooth trend over
    the dome the Gaussians alone would let fall to 0 between sparse lights)."""
    d = np.linalg.norm(np.asarray(a)[:, None, :2] - np.asarray(b)[None, :, :2], axis=-1)
    out = np.exp(-(eps * d) ** 2)
    if mix:
        out = out + mix * (hsh_basis(a, 2) @ hsh_basis(b, 2).T)
    return out


def _loo_error(kern, ridge, gram):
    """Σ over rows r of R (gram = RᵀR) of the squared leave-one-out errors of kernel ridge
    regression through r: e = A r / diag(A), A = (K + ridge I)⁻¹ (exact, no refit)."""
    a = np.linalg.inv(kern + ridge * np.eye(len(kern)))
    loo = a / np.diag(a)[None]
    return float(np.sum(loo * (gram @ loo)))         # Σ_j loo_jᵀ G loo_j (a product, not a triple loop)


def _kernel_choice(gram, dirs, spacing):
    """(epsilon, mix, ridge) of the kernel ridge regression that interpolates the residual's
    light functions, or None when none predicts MIN_PREDICTED of the residual's energy at the
    fitted lights left out (noise: ~0.004 %).
    gram (m, m) = Σ over pixel-channels of r rᵀ (the residual kept). Judged by the exact
    leave-one-light-out error of kernel ridge (Rasmussen & Williams 2006, eq. 5.12: e = A r / diag A,
    A = (K + λI)⁻¹), summed over every pixel and channel: trace(D⁻¹A G A D⁻¹), from the gram alone."""
    m = len(dirs)
    best, best_err = None, (1.0 - MIN_PREDICTED) * float(np.trace(gram))
    for mult in RBF_WIDTHS:
        for mix in HSH_MIX:
            kern = _kernel(dirs, dirs, 1.0 / (mult * spacing), mix)
            scale = float(np.trace(kern)) / m
            for sm in RBF_SMOOTHING:
                err = _loo_error(kern, sm * scale, gram)
                if err < best_err:
                    best, best_err = (1.0 / (mult * spacing), mix, sm * scale), err
    return best, (best_err if best is not None else float(np.trace(gram)))


def default_planes(m, n_pixels=0):
    """Residual planes for m fitted lights: the principal components of the residual over the
    lights, as many as the lights, at most MAX_PLANES and what PLANES_BYTES holds for n_pixels
    (12 MP: 7 planes), at least 4; none below 6 lights. More planes predict better (DiLiGenT's
    crops, 84 lights, held out: 16 → 48 planes +0.3 to +0.7 dB; the dome, 200: +1.6 dB)."""
    if m < 6:
        return 0
    fits = PLANES_BYTES // max(6 * int(n_pixels), 1)
    return int(max(4, min(m, MAX_PLANES, fits)))


_ARRAYS = ("normals", "mask", "rho", "spec", "amb", "heights", "planes", "centres", "weights", "trend")


WRITE_BYTES = 1 << 26        # an array's bytes written at a time (`_write_npz`)


def save_relight_model(path, model):
    """Write a `RelightModel` to an .npz (uncompressed, written whole or not at all; its arrays a band
    of rows at a time: a spilled model's pages handed back after each, `_write_npz`)."""
    arrays = {k: getattr(model, k) for k in _ARRAYS if getattr(model, k) is not None}
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        _write_npz(fh, dict(format=np.array("facette relight model 1"), shininess=model.shininess,
                            epsilon=model.epsilon, white=model.white, softness=model.softness,
                            spacing=model.spacing, reach=model.reach, **arrays))


def _write_npz(fh, arrays):
    """np.savez's file (a stored zip of .npy members, zip64), each array written WRITE_BYTES at a time
    along its first axis, a disk array's pages handed back after each (`_memory.release`): np.savez
    reads a memmap whole into the process's memory (100 MP: the model's 8 GB)."""
    with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name, value in arrays.items():
            a = np.asanyarray(value)
            with zf.open(name + ".npy", "w", force_zip64=True) as out:
                if a.ndim == 0 or a.dtype.hasobject:
                    np.lib.format.write_array(out, a, allow_pickle=False)
                    continue
                header = dict(np.lib.format.header_data_from_array_1_0(a), fortran_order=False)   # rows in C order
                np.lib.format.write_array_header_1_0(out, header)
                rows = max(1, WRITE_BYTES // max(1, a[:1].nbytes))
                for r0 in range(0, len(a), rows):
                    out.write(np.ascontiguousarray(a[r0:r0 + rows]).tobytes())
                    release(a)


def load_relight_model(path):
    """Read what `save_relight_model` wrote. Raises BadInputError for another file."""
    try:
        with np.load(path) as z:
            if "format" not in z or not str(z["format"]).startswith("facette relight model"):
                raise BadInputError(f"{path} is not a facette relighting model",
                                    hint="give the relight_model.npz that facette process wrote")
            got = {k: z[k] for k in _ARRAYS if k in z}
            return RelightModel(shininess=float(z["shininess"]), epsilon=float(z["epsilon"]),
                                white=float(z["white"]), softness=float(z["softness"]),
                                spacing=float(z["spacing"]), reach=float(z["reach"]),
                                **{k: got.get(k) for k in _ARRAYS})
    except BadInputError:
        raise
    except (OSError, ValueError, KeyError) as exc:
        raise BadInputError(f"cannot read the relighting model {path}: {exc}",
                            hint="give the relight_model.npz that facette process wrote") from exc
