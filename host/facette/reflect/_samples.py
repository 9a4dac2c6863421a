"""Reflectance samples from the HDR images and the estimated normals (thesis eq 4.11).

Each sample is one (pixel, light, channel) value f = E / (k (n.s)), with its incidence and
observation directions rotated into the local frame of the normal (n = +z) and about n so
that the incidence lies in the half-plane phi_s = 0 (thesis §4.2.2, fig 4.17).

Eq 4.10-4.11 write the source term as L_i(o); the radiance that arrives is the source's,
from direction s (one LED per image): L_i here is the calibrated intensity of that light.
"""
from dataclasses import dataclass

import numpy as np

__all__ = ["ReflectanceSamples", "reflectance_samples", "samples_from_pixels", "sample_angles", "sample_grid",
           "local_frame_directions", "MIN_COS"]

MIN_COS = 0.05   # samples with n.s below this (incidence beyond ~87 deg) divide noise by ~0


@dataclass
class ReflectanceSamples:
    """Flat arrays of K samples.

    s, o : (K, 3) float32 unit vectors in the local frame (n = +z, s_y = 0, s_x >= 0).
    f : (K, C) float32 BRDF estimates (1/sr when images are radiance per unit irradiance).
    pixel : (K,) int64 flat pixel index (row * W + col); light : (K,) int16 light index.
    """
    s: np.ndarray
    o: np.ndarray
    f: np.ndarray
    pixel: np.ndarray
    light: np.ndarray

    def __len__(self):
        return len(self.f)

    def subset(self, index):
        return ReflectanceSamples(self.s[index], self.o[index], self.f[index], self.pixel[index],
                                  self.light[index])


def local_frame_directions(n, s, o):
    """Rotate unit vectors into the frame of n, turned about n so that phi_s = 0.

    n, s, o : (..., 3) unit vectors (camera frame), broadcasting. Returns (s_local, o_local),
    each (..., 3): s_local = (sin theta_s, 0, cos theta_s), o_local keeps the angles of o to n
    and to the incidence plane. Where s is parallel to n any tangent is used (phi is undefined).
    """
    n, s, o = np.broadcast_arrays(*(np.asarray(v, dtype=np.float32) for v in (n, s, o)))
    sn = np.sum(s * n, axis=-1, keepdims=True)
    t = s - sn * n
    tn = np.linalg.norm(t, axis=-1, keepdims=True)
    # fallback tangent when s // n: anything perpendicular to n
    alt = np.cross(n, np.where(np.abs(n[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]))
    alt /= np.maximum(np.linalg.norm(alt, axis=-1, keepdims=True), 1e-12)
    t = np.where(tn > 1e-6, t / np.maximum(tn, 1e-12), alt)
    b = np.cross(n, t)
    s_loc = np.concatenate([np.sum(s * t, -1, keepdims=True), np.zeros_like(sn), sn], axis=-1)
    o_loc = np.stack([np.sum(o * t, -1), np.sum(o * b, -1), np.sum(o * n, -1)], axis=-1)
    return s_loc.astype(np.float32), o_loc.astype(np.float32)


def reflectance_samples(images, normals, light_dirs, mask=None, exclude=None, view=(0.0, 0.0, 1.0),
                        k=1.0, min_cos=MIN_COS):
    """BRDF samples per pixel, light and channel (thesis eq 4.11): f = E / (k L_i (n.s) dw_s).

    images : (m, H, W) or (m, H, W, C) linear radiance already divided by each light's
        intensity L_i dw_s (so a Lambertian surface of reflectance rho gives f = rho / pi).
    normals : (H, W, 3) unit vectors (camera frame); zero or non-finite ones are skipped.
    light_dirs : (m, 3) unit vectors towards the lights, or (H, W, m, 3) per pixel.
    mask : (H, W) bool pixels to use; exclude : optional (H, W, m) bool samples to leave out
        (e.g. the shadows found by photometric stereo).
    view : unit vector towards the camera (orthographic: +z). k : camera constant of eq 4.8
        ((pi/4)(d_l/f)^2 cos^4 alpha); 1 when the intensity calibration already includes it.
    min_cos : samples with n.s < min_cos, or n.o <= 0, or a non-finite E are left out.
    Returns `ReflectanceSamples`.
    """
    images = np.asarray(images, dtype=np.float32)
    if images.ndim == 3:
        images = images[..., None]
    if images.ndim != 4:
        raise ValueError(f"images must have shape (m, H, W) or (m, H, W, C), got {images.shape}")
    m, h, w, c = images.shape
    normals = np.asarray(normals, dtype=np.float32)
    if normals.shape != (h, w, 3):
        raise ValueError(f"normals must have shape ({h}, {w}, 3), got {normals.shape}")
    light_dirs = np.asarray(light_dirs, dtype=np.float32)
    if light_dirs.shape not in ((m, 3), (h, w, m, 3)):
        raise ValueError(f"light_dirs must have shape ({m}, 3) or ({h}, {w}, {m}, 3), got {light_dirs.shape}")
    if not k > 0:
        raise ValueError(f"k must be positive, got {k}")
    _check_min_cos(min_cos)
    ok_n = np.all(np.isfinite(normals), -1) & (np.linalg.norm(np.nan_to_num(normals), axis=-1) > 0.5)
    if mask is not None:
        ok_n &= np.asarray(mask, bool)
    if exclude is not None:
        exclude = np.asarray(exclude, bool)
        if exclude.shape != (h, w, m):
            raise ValueError(f"exclude must have shape ({h}, {w}, {m}), got {exclude.shape}")
    pix = np.flatnonzero(ok_n.ravel())
    n = normals.reshape(-1, 3)[pix]                                       # (P, 3)
    s = light_dirs if light_dirs.ndim == 2 else light_dirs.reshape(h * w, m, 3)[pix]
    e = images.reshape(m, h * w, c)[:, pix]                              # (m, P, C)
    ex = None if exclude is None else exclude.reshape(h * w, m)[pix].T
    out = samples_from_pixels(e, n, s, ex, view, k, min_cos)
    out.pixel = pix[out.pixel]
    return out


def sample_angles(e, n, s, exclude=None, view=(0.0, 0.0, 1.0), k=1.0, min_cos=MIN_COS):
    """The core of eq 4.11 on gathered pixels, light-major, without building rotation matrices.

    e : (m, P, C); n : (P, 3) unit; s : (m, 3) or (P, m, 3); exclude : (m, P) bool or None.
    In the frame of n turned so that phi_s = 0: s_local = (sin ts, 0, cos ts) with cos ts = n.s,
    o_local = ((s.o - (n.s)(n.o)) / sin ts, n.(s x o) / sin ts, n.o).
    Returns (light (K,), pixel (K,), cos_s (K,), o_local (K, 3), f (K, C)) for the kept samples.
    """
    o = np.asarray(view, dtype=np.float32)
    n = np.asarray(n, dtype=np.float32)
    s = np.asarray(s, dtype=np.float32)
    if s.ndim == 2:
        ns = s @ n.T                                   # (m, P)
        so = (s @ o)[:, None]
        sxo = np.cross(s, o) @ n.T                     # n.(s x o)
    else:
        ns = np.einsum("pmi,pi->mp", s, n)
        so = np.einsum("pmi,i->mp", s, o)
        sxo = np.einsum("pmi,pi->mp", np.cross(s, o), n)
    no = n @ o                                         # (P,)
    keep = (ns >= min_cos) & (no > 0)[None, :]
    keep &= np.all(np.isfinite(e), axis=-1)
    if exclude is not None:
        keep &= ~exclude
    li, pi_ = np.nonzero(keep)
    cs = ns[li, pi_]
    sin_s = np.sqrt(np.maximum(1 - cs * cs, 0))
    cz = no[pi_]
    safe = np.where(sin_s > 1e-6, sin_s, 1.0)
    ox = np.where(sin_s > 1e-6, (so[li, pi_ if so.shape[1] > 1 else 0] - cs * cz) / safe,
                  np.sqrt(np.maximum(1 - cz * cz, 0)))        # s // n: phi undefined, use phi_o = 0
    oy = np.where(sin_s > 1e-6, sxo[li, pi_] / safe, 0.0)
    o_loc = np.stack([ox, oy, cz], axis=1).astype(np.float32)
    f = (e[li, pi_] / (k * cs)[:, None]).astype(np.float32)
    return li, pi_, cs.astype(np.float32), o_loc, f


def _check_min_cos(min_cos):
    if not min_cos > 0:
        raise ValueError(f"min_cos must be > 0 (got {min_cos}): eq 4.11 divides by n.s, which "
                         "is 0 at grazing incidence")


def sample_grid(e, n, s, exclude=None, view=(0.0, 0.0, 1.0), k=1.0, min_cos=MIN_COS,
                check_finite=True):
    """Eq 4.11 on a whole (light, pixel) grid, nothing gathered (for the hemisphere sensor).

    e : (m, P, C); n : (P, 3) unit; s : (m, 3) or (P, m, 3); exclude : (m, P) bool or None.
    Returns dict of cos_s (m, P), o_x, o_y (m, P), cos_o (P,), keep (m, P) and scale (m, P) =
    1 / (k n.s) where kept, 0 elsewhere, so that f = e * scale[..., None]; the local frame as in
    `sample_angles`. check_finite=False skips the NaN test (when the caller knows e is finite).
    """
    _check_min_cos(min_cos)
    o = np.asarray(view, dtype=np.float32)
    n = np.asarray(n, dtype=np.float32)
    s = np.asarray(s, dtype=np.float32)
    if s.ndim == 2:
        ns = s @ n.T
        so = (s @ o)[:, None]
        sxo = np.cross(s, o) @ n.T
    else:
        ns = np.einsum("pmi,pi->mp", s, n)
        so = np.einsum("pmi,i->mp", s, o)
        sxo = np.einsum("pmi,pi->mp", np.cross(s, o), n)
    no = n @ o
    keep = (ns >= min_cos) & (no > 0)[None, :]
    if exclude is not None:
        keep &= ~exclude
    if check_finite:
        keep &= np.isfinite(e).all(axis=-1)
    sin_s = np.sqrt(np.maximum(1 - ns * ns, 1e-12))
    inv = 1.0 / sin_s
    o_x = (so - ns * no) * inv
    o_y = sxo * inv
    flat = sin_s < 1e-5                        # s along n: phi undefined, put o at phi = 0
    if flat.any():
        li, pi_ = np.nonzero(flat)
        o_x[li, pi_] = np.sqrt(np.maximum(1 - no[pi_] ** 2, 0))
        o_y[li, pi_] = 0.0
    # ns >= min_cos > 0 wherever keep is set
    scale = keep / (np.float32(k) * np.maximum(ns, np.float32(min_cos)))
    return dict(cos_s=ns, o_x=o_x, o_y=o_y, cos_o=no, keep=keep, scale=scale.astype(np.float32))


def samples_from_pixels(e, n, s, exclude=None, view=(0.0, 0.0, 1.0), k=1.0, min_cos=MIN_COS):
    """`reflectance_samples` on pixels already gathered: e (m, P, C), n (P, 3) unit,
    s (m, 3) or (P, m, 3), exclude (m, P) bool or None. `pixel` in the result indexes P."""
    li, pi_, cs, o_loc, f = sample_angles(e, n, s, exclude, view, k, min_cos)
    s_loc = np.stack([np.sqrt(np.maximum(1 - cs * cs, 0)), np.zeros_like(cs), cs], axis=1)
    return ReflectanceSamples(s_loc, o_loc, f, pi_.astype(np.int64), li.astype(np.int16))
