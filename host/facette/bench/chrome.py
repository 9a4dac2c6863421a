"""`facette bench chrome`: light directions from a photographed chrome sphere, and photometric
stereo with them.

On the Goldman–Seitz set (../shared/data/psm_goldman_seitz/, or --root DIR): the 12 lights from
the chrome ball's own photographs (`calib.mirror_sphere_directions`: the outline found on its dark
background, then given as the set's mask) against the set's `light_directions.txt` (mean and worst
angle, run time); how far those reference directions are from any one orthographic mirror sphere
(the sphere fitted to them, and the pixel distance left between where they put each highlight and
where it is); then least-squares photometric stereo of each object of the set with both sets of
directions: the relative RMS residual of the Lambertian fit and the mean angle between the two
normal maps.
"""
import argparse
import time
from pathlib import Path

import numpy as np
from scipy import optimize

import facette
from facette.calib.mirror_sphere import mirror_sphere_directions
from facette.io.png import read_mask
from facette.recon import ps_woodham1980

OBJECTS = ("buddha", "cat", "gray", "horse", "owl", "rock")


def _read_set(folder):
    import cv2

    names = (folder / "filenames.txt").read_text().split()
    ims = np.stack([cv2.imread(str(folder / n), cv2.IMREAD_UNCHANGED)[..., ::-1] for n in names])
    return ims.astype(np.float32), np.loadtxt(folder / "light_directions.txt")


def _angles(a, b):
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1, 1)))


def _reference_consistency(ref_dirs, circle, highlights):
    """Fit one orthographic mirror sphere (cx, cy, r) to the reference directions and the found
    highlights: the pixel residual per light says whether any sphere gives those directions."""
    n = ref_dirs + np.array([0.0, 0.0, 1.0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    p = np.array([(h.x, h.y) for h in highlights])

    def res(q):
        return np.r_[q[0] + q[2] * n[:, 0] - p[:, 0], q[1] - q[2] * n[:, 1] - p[:, 1]]
    sol = optimize.least_squares(res, [circle.cx, circle.cy, circle.r])
    d = np.hypot(*sol.fun.reshape(2, -1))
    return sol.x, d


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench chrome", description=__doc__.splitlines()[0])
    default_root = Path(facette.__file__).resolve().parents[2].parent / "shared" / "data"
    ap.add_argument("--root", default=str(default_root), help=f"real data folder (default {default_root})")
    args = ap.parse_args(argv)
    base = Path(args.root) / "psm_goldman_seitz"
    if not (base / "chrome" / "filenames.txt").is_file():
        print(f"no Goldman–Seitz chrome set under {base} (pass --root DIR); skipped")
        return 0
    ims, ref = _read_set(base / "chrome")
    print(f"1. chrome sphere, {len(ims)} photographs {ims.shape[2]}x{ims.shape[1]}, 8-bit: directions "
          "against light_directions.txt")
    print(f"  {'outline':22s} {'circle (cx, cy, r) px':28s} {'mean':>7s} {'worst':>7s}  per light (deg)"
          f"{'':30s} {'time':>7s}")
    found = None
    for label, kw in (("found in the photos", {}),
                      ("given as mask.png", {"mask": read_mask(base / "chrome" / "mask.png")})):
        t0 = time.perf_counter()
        dirs, c, hl = mirror_sphere_directions(ims, white_level=255, **kw)
        dt = time.perf_counter() - t0
        err = _angles(dirs, ref)
        found = found or (dirs, c, hl)
        print(f"  {label:22s} ({c.cx:6.1f}, {c.cy:6.1f}, {c.r:6.1f}) {'':5s} {err.mean():6.2f}° "
              f"{err.max():6.2f}°  {' '.join(f'{e:.1f}' for e in err)}  {dt:6.2f} s")
    dirs, c, hl = found
    q, d = _reference_consistency(ref, c, hl)
    print(f"  the one mirror sphere nearest the reference directions: ({q[0]:.1f}, {q[1]:.1f}, {q[2]:.1f}) "
          f"px; it puts the highlights {d.mean():.1f} px (mean), {d.max():.1f} px (worst, light "
          f"{int(np.argmax(d))}) from where they are in the photographs")
    print("2. least-squares photometric stereo of the set's objects (8-bit, pixels in 5..250 under every "
          "light): with the reference directions / with the sphere's")
    print("  (residual: mean relative least-squares residual ||E - S g|| / ||E|| on green)")
    print(f"  {'object':8s} {'residual ref':>13s} {'residual ours':>14s} {'normals apart':>14s} {'time':>7s}")
    for obj in OBJECTS:
        folder = base / obj
        if not (folder / "filenames.txt").is_file():
            continue
        imgs, _ = _read_set(folder)
        mask = read_mask(folder / "mask.png")
        g = imgs.mean(axis=3)
        ok = mask & np.all((g > 5) & (g < 250), axis=0)
        out = []
        t0 = time.perf_counter()
        for L in (ref, dirs):
            r = ps_woodham1980(imgs, L, ok)
            out.append((r.normal, float(np.mean(r.residual[ok & r.valid]))))
        dt = time.perf_counter() - t0
        apart = _angles(out[0][0][ok], out[1][0][ok]).mean()
        print(f"  {obj:8s} {out[0][1]:13.4f} {out[1][1]:14.4f} {apart:13.2f}° {dt:6.2f} s")
    return 0
