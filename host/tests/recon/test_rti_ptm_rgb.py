"""recon._rti_ptm_rgb: the per-channel PTM fit and the leave-one-light-out errors that choose
relight.ptm's format, against refitting without each light."""
import numpy as np

from facette.recon import fit_ptm_lrgb, ptm_basis
from facette.recon._rti_jit import display_inplace
from facette.recon._rti_photo import PHOTO_RCOND, _display_table
from facette.recon._rti_ptm_rgb import fit_ptm_rgb, ptm_loo_parts
from facette.recon.synthetic import render, sphere_on_plane

M = 16


def _capture():
    az = np.radians(np.arange(M) * 360.0 / M)
    el = np.radians(np.tile([25.0, 40.0, 55.0, 70.0], M // 4))
    dirs = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]
    imgs = render(sphere_on_plane(20, 24, radius=8), dirs, "satin", albedo=(0.7, 0.1, 0.05), cast_shadows=False, ks=3.0)
    return np.clip(imgs / np.percentile(imgs, 99.5), 0, 1).astype(np.float32), dirs


def _refit(y, basis, k):
    """A pixel's per-channel PTM (ridge as photographed) without light k, at light k: (3,)."""
    keep = np.arange(len(y)) != k
    a = basis[keep]
    ata = a.T @ a
    ata += PHOTO_RCOND * np.trace(ata) * np.eye(6)
    return np.clip(basis[k] @ np.linalg.solve(ata, a.T @ y[keep]), 0, 1)


def test_leave_one_light_out_errors_are_refits_without_that_light():
    imgs, dirs = _capture()
    lrgb = fit_ptm_lrgb(imgs, dirs, white=1.0, encoding="srgb", photographed=True)
    rgb = fit_ptm_rgb(imgs, dirs, 1.0, "srgb")
    shown = imgs.copy()
    display_inplace(shown, 1.0, _display_table("srgb"))
    mask = np.zeros((20, 24), bool)
    mask[[4, 10, 13], [12, 9, 16]] = True             # the sphere's body, its highlight side, the plane
    parts = ptm_loo_parts(lrgb, rgb, imgs, dirs, mask, range(20), rows=1)
    basis = ptm_basis(dirs)
    want = sum(float(np.sum((shown[k, i, j] - _refit(shown[:, i, j].astype(float), basis, k)) ** 2))
               for i, j in zip(*np.nonzero(mask)) for k in range(M))
    n = sum(p[2] for p in parts)
    assert n == 3 * M * 3
    assert np.isclose(sum(p[1] for p in parts), want, rtol=1e-3)     # float32 coefficients, the ridge of all lights
    # the LRGB's: its luminance refitted without the light, its colour kept
    col = lrgb.rgb[4, 12].astype(float)
    lum = shown[:, 4, 12].astype(float) @ col / (col @ col)
    want_l = 0.0
    for k in range(M):
        keep = np.arange(M) != k
        a = basis[keep]
        ata = a.T @ a
        ata += PHOTO_RCOND * np.trace(ata) * np.eye(6)
        held = basis[k] @ np.linalg.solve(ata, a.T @ lum[keep])
        want_l += float(np.sum((shown[k, 4, 12] - np.clip(held * col, 0, 1)) ** 2))
    one = np.zeros_like(mask)
    one[4, 12] = True
    got = ptm_loo_parts(lrgb, rgb, imgs, dirs, one, [4], rows=1)[0]
    assert np.isclose(got[0], want_l, rtol=1e-3)
    assert ptm_loo_parts(lrgb, rgb, imgs, np.broadcast_to(dirs, (20, 24, M, 3)), mask, range(20)) is None


def test_per_channel_fit_is_each_channels_least_squares():
    imgs, dirs = _capture()
    rgb = fit_ptm_rgb(imgs, dirs, 1.0, "linear")
    assert rgb.coeffs.shape == (20, 24, 3, 6) and rgb.valid.all() and rgb.CONSTANT == 5
    a = ptm_basis(dirs)
    ata = a.T @ a
    ata += PHOTO_RCOND * np.trace(ata) * np.eye(6)
    want = np.linalg.solve(ata, a.T @ imgs[:, 7, 11].astype(float))          # (6, 3)
    np.testing.assert_allclose(rgb.coeffs[7, 11], want.T, atol=2e-5)
    np.testing.assert_allclose(rgb.basis(dirs[:2]), a[:2])
