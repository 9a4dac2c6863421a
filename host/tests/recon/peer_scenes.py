"""Synthetic scenes for the published peers' tests (test_ps_peers, test_ps_consensus): a sphere
under distant lights spread like DiLiGenT's, shaded by a Blinn-Phong lobe over a Lambertian term."""
import numpy as np


def lights(m=40, seed=3):
    """m directions within 10-60° of the view (as DiLiGenT's)."""
    rng = np.random.default_rng(seed)
    th = np.arccos(rng.uniform(np.cos(np.radians(60)), np.cos(np.radians(10)), m))
    ph = rng.uniform(0, 2 * np.pi, m)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1)


def sphere(size=40):
    """(normals (size, size, 3), mask) of a sphere filling 90 % of the frame (0 outside)."""
    y, x = np.mgrid[1:-1:size * 1j, -1:1:size * 1j]
    r2 = x * x + y * y
    mask = r2 < 0.9 ** 2
    n = np.stack([x, y, np.sqrt(np.clip(1 - r2, 0, 1))], -1)
    return np.where(mask[..., None], n, 0), mask


def blinn_phong(n, lights, kd=0.5, ks=0.6, shininess=40.0, noise=0.0, seed=0):
    """(m, H, W) E = (kd/π) (n·l)_+ + ks (n·h)^s (n·l)_+ (a Blinn-Phong lobe), camera along +z."""
    h = lights + np.array([0, 0, 1.0])
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    nl = np.clip(np.einsum("hwk,mk->mhw", n, lights), 0, None)
    nh = np.clip(np.einsum("hwk,mk->mhw", n, h), 0, None)
    img = kd / np.pi * nl + ks * nh ** shininess * nl
    if noise:
        img *= 1 + noise * np.random.default_rng(seed).standard_normal(img.shape)
    return img.astype(np.float32)
