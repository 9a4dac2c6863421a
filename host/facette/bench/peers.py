"""`facette bench peers`: published photometric-stereo methods beside ours, with the papers' figures.

DiLiGenT (the shared objects: the 16-bit ball and the 8-bit crops, found as `facette bench
diligent` finds them, the same grey input; each 16-bit object also cut to 8 bits as the crops
were, floor(value / 256), the row "16-bit cut to": what 8 bits cost on the same object): per object and method the mean angular error and
the run time, and for the peers the figure their paper reports on that object (Shi et al.'s
DiLiGenT table, all 96 lights, full 16-bit images; `facette.bench.diligent.PUBLISHED_OTHERS`).
Methods: least squares, rank_trimmed (the default), li_alternating (the BRDF-aware solve) and
the peers of `facette.recon._ps_peers` (ST14 bi-polynomial, IA14 bivariate regression) and
`facette.recon._ps_consensus` (HM10 consensus; no paper figure printed: see PUBLISHED_OTHERS).

Then (unless --no-mitsuba) Mitsuba 3 renders of materials the LI model does not cover
(`facette.bench._mitsuba_scenes.NON_LI_SCENES`: gold and aluminium `roughconductor`, a metallic
paint `blendbsdf`, a rough plastic α 0.4, textured albedo), 12 rig lights, each method's mean
error, its ratio to least squares and its time. Errors are taken on the pixels that some light
shows (brightest value at least LIT_SHARE of the scene's 99th percentile of brightest values):
a metal has no diffuse part, and on a sphere under the rig's lights (15° and 30° from the view)
its normals beyond about 25° from the view reflect no light towards the camera at all, black in
every image; the share of such pixels is printed with each scene.
"""
import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import binary_erosion

from facette.bench._mitsuba_scenes import NON_LI_SCENES, render_scene
from facette.bench.diligent import PUBLISHED_OTHERS, default_root, find_objects, object_name, run_object
from facette.bench.mitsuba import angular_errors as _angles
from facette.bench.mitsuba import run_ps as mitsuba_run_ps
from facette.methods import PS_METHODS

METHODS = ("woodham1980", "rank_trimmed", "li_alternating", "bipolynomial_shi2014", "bivariate_ikehata2014",
           "consensus_higo2010")
LIT_SHARE = 0.01       # a pixel whose brightest value is below this share of the scene's is dark
PAPER_OBJECTS = ("ball", "cat", "pot2", "buddha", "reading")    # the order of PUBLISHED_OTHERS
PAPER_OF = {"bipolynomial_shi2014": "Shi 2014 bi-polynomial", "bivariate_ikehata2014": "Ikehata 2014 bivariate",
            "consensus_higo2010": "Higo 2010 consensus"}


def read_bit_depth(folder):
    """8 or 16: the bit depth of the folder's first image."""
    from facette.io.png import read_png
    first = (folder / "filenames.txt").read_text().split()[0]
    return 16 if read_png(folder / first).dtype == np.uint16 else 8


def paper_figure(method, obj):
    """The paper's mean error (deg) for a peer on a DiLiGenT object, or None."""
    key = PAPER_OF.get(PS_METHODS.canonical(method)) if method in PS_METHODS else None
    if key not in PUBLISHED_OTHERS or obj not in PAPER_OBJECTS:      # HM10's: not verified
        return None
    return PUBLISHED_OTHERS[key][PAPER_OBJECTS.index(obj)]


def requantised(folder, dest):
    """A copy of the DiLiGenT folder at dest with every 16-bit image cut to 8 bits as the shared
    crops were made (floor(value / 256)): what the 8-bit crops cost, on the same object."""
    import shutil
    from facette.io.png import read_png, write_png
    dest.mkdir(parents=True)
    for f in folder.iterdir():
        if f.suffix.lower() == ".png" and f.name != "mask.png":
            img = read_png(f)
            write_png(dest / f.name, (img // 256).astype(np.uint8) if img.dtype == np.uint16 else img)
        elif f.is_file():
            shutil.copy(f, dest / f.name)
    return dest


def diligent_table(methods, root, tmp=None):
    objects = [(f, t) for f, t in find_objects(root) if t is not None]
    if tmp is not None:     # each 16-bit object again, cut to 8 bits (its truth beside it)
        for f, t in [(f, t) for f, t in objects if read_bit_depth(f) == 16]:
            q = requantised(f, Path(tmp) / "requantised_to_8_bit" / f.name)
            objects.append((q, t))
    if not objects:
        print(f"no DiLiGenT-style folder with truth under {root}; give one with --root DIR")
        return 1
    print("\n-- DiLiGenT, all lights, grey input: mean angular error (deg) and run time (s); "
          "[paper]: the method's own figure on that object (96 lights, 16-bit)")
    print(f"{'object':28s}" + "".join(f" | {m[:24]:>24s}" for m in methods))
    sums = {m: [] for m in methods}
    for folder, truth in objects:
        rows, _, data = run_object(folder, truth, methods, "all")
        obj = object_name(folder)
        place = "16-bit cut to " if folder.parent.name == "requantised_to_8_bit" else folder.parent.name + "/"
        line = f"{place + obj + f' {data.bit_depth}-bit':28s}"
        for name, mean, _, dt in rows:
            pub = paper_figure(name, obj)
            cell = f"{mean:6.2f} {dt:6.1f}s" + (f" [{pub:5.2f}]" if pub is not None else " " * 8)
            line += f" | {cell:>24s}"
            if data.bit_depth == 8 and place != "16-bit cut to ":      # the shipped 8-bit crops
                sums[name].append((mean, dt, pub))
        print(line, flush=True)
    line = f"{'mean of the 8-bit crops':28s}"
    for m in methods:
        errs = [r[0] for r in sums[m]]
        pubs = [r[2] for r in sums[m]]
        cell = f"{np.mean(errs):6.2f} {np.sum([r[1] for r in sums[m]]):6.1f}s"
        if all(p is not None for p in pubs):
            cell += f" [{np.mean(pubs):5.2f}]"
        line += f" | {cell:>24s}"
    print(line + "   (time: total)")
    return 0


def mitsuba_table(methods, cache, size, spp):
    print(f"\n-- Mitsuba 3, materials outside the LI model, {size}x{size} px, {spp} spp, 12 rig lights: "
          "mean error (deg) / ratio to least squares / run time (s), mask eroded by 1 px, on the lit "
          f"pixels (brightest value >= {LIT_SHARE:g} x the scene's; the dark share after the name)")
    print(f"{'scene':42s}" + "".join(f" | {m[:24]:>24s}" for m in methods))
    for shape, mat, tex in NON_LI_SCENES:
        t = time.perf_counter()
        d = render_scene(shape, mat, size=size, spp=spp, textured=tex, cache_dir=cache)
        if time.perf_counter() - t > 1:
            print(f"  (rendered {shape}/{mat} in {time.perf_counter() - t:.0f} s)", file=sys.stderr, flush=True)
        sel = binary_erosion(d["mask"], iterations=1)
        brightest = d["images"][..., 1].max(axis=0)
        lit = brightest >= LIT_SHARE * np.percentile(brightest[sel], 99)
        dark = 1 - float((sel & lit).sum()) / max(int(sel.sum()), 1)
        sel &= lit
        ls = None
        line = f"{shape + '/' + mat + (' textured' if tex else '') + f' ({dark:.0%} dark)':42s}"
        for m in methods:
            r, dt = mitsuba_run_ps(d, m)
            e = _angles(r.normal, d["normals"], sel).mean()
            ls = e if PS_METHODS.canonical(m) == "woodham1980" else ls
            ratio = f"{e / ls:5.2f}x" if ls else "   n/a"
            line += f" | {f'{e:6.2f} {ratio} {dt:6.2f}s':>24s}"
        print(line, flush=True)
    return 0


ST14_GRID = ((0.02, 0.25), (0.02, 0.5), (0.02, 0.75), (0.1, 0.25), (0.1, 0.5), (0.1, 0.75))   # (t_shadow, t_low)


def st14_render(material, levels, floor, size=64, m=96, seed=0):
    """A rendered sphere for choosing ST14's constants (never DiLiGenT): (images, lights, mask,
    normals). m lights 10-60° from the view (DiLiGenT's spread); material "blinn" (Lambert 0.5 +
    Blinn-Phong 0.6, exponent 40), "satin" or "glossy" (Cook-Torrance as facette.recon.synthetic);
    `floor` stray light in every image (share of the diffuse peak), 0.5 % noise, values cut down
    to `levels` grey levels at the diffuse peak (floor(v), as the shared 8-bit crops were)."""
    from facette.recon.synthetic import _cook_torrance
    rng = np.random.default_rng(seed)
    th = np.arccos(rng.uniform(np.cos(np.radians(60)), np.cos(np.radians(10)), m))
    ph = rng.uniform(0, 2 * np.pi, m)
    lights = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1)
    y, x = np.mgrid[1:-1:size * 1j, -1:1:size * 1j]
    mask = x * x + y * y < 0.9 ** 2
    n = np.where(mask[..., None], np.stack([x, y, np.sqrt(np.clip(1 - x * x - y * y, 0, 1))], -1), 0)
    v = np.array([0.0, 0.0, 1.0])
    nl = np.clip(np.einsum("hwk,mk->mhw", n, lights), 0, None)
    if material == "blinn":
        h = (lights + v) / np.linalg.norm(lights + v, axis=1, keepdims=True)
        img = 0.5 / np.pi * nl + 0.6 * np.clip(np.einsum("hwk,mk->mhw", n, h), 0, None) ** 40 * nl
    else:
        sig, n_i = {"satin": (0.15, 1.3), "glossy": (0.05, 1.2)}[material]
        img = np.nan_to_num(np.stack([_cook_torrance(n, np.broadcast_to(s, n.shape), np.broadcast_to(v, n.shape),
                                                     [0.5], 1.0, sig, n_i)[..., 0] * nl[i]
                                      for i, s in enumerate(lights)]))
    img = (img + floor * 0.5 / np.pi) * (1 + 0.005 * rng.standard_normal(img.shape))
    scale, top = levels / (0.5 / np.pi), (255 if levels < 256 else 65535)
    q = np.floor(np.clip(img * scale, 0, top))
    return np.where(q >= top, np.nan, q / scale).astype(np.float32), lights, mask, n


def st14_choice():
    """ST14's shadow threshold and low-frequency share on renders (how ST14_T_SHADOW and
    ST14_T_LOW were chosen): mean error (deg) per render and setting, and the mean."""
    from facette.recon import ps_bipolynomial_shi2014
    print("\n-- ST14 constants on rendered spheres (96 lights, 0.5 % noise): mean error (deg) per "
          "(t_shadow, t_low)")
    print(f"{'render':34s}" + "".join(f" | {f'{a:g}, {b:g}':>10s}" for a, b in ST14_GRID))
    sums = np.zeros(len(ST14_GRID))
    cases = [(mat, lv, fl) for mat in ("blinn", "satin", "glossy") for lv in (40, 10000) for fl in (0.0, 0.02)]
    for mat, lv, fl in cases:
        img, lights, mask, n = st14_render(mat, lv, fl)
        line = f"{mat} {'8-bit, 40 levels' if lv < 256 else '16-bit'} floor {fl:g}"
        line = f"{line:34s}"
        for j, (ts, tl) in enumerate(ST14_GRID):
            r = ps_bipolynomial_shi2014(img, lights, mask, t_shadow=ts, t_low=tl)
            e = np.degrees(np.arccos(np.clip(np.sum(r.normal * n, -1), -1, 1)))[mask].mean()
            sums[j] += e / len(cases)
            line += f" | {e:10.2f}"
        print(line, flush=True)
    print(f"{'mean':34s}" + "".join(f" | {s:10.2f}" for s in sums))
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench peers", description=__doc__.splitlines()[0])
    ap.add_argument("--root", default=None, help="folder searched for DiLiGenT-style folders (default ../shared/data)")
    ap.add_argument("--methods", default=",".join(METHODS), help="comma-separated (least squares first: the ratios)")
    ap.add_argument("--no-real", action="store_true", help="skip the DiLiGenT table")
    ap.add_argument("--no-mitsuba", action="store_true",
                    help="skip the Mitsuba renders of metals, metallic paint, rough plastic (about 4 min to render once)")
    ap.add_argument("--st14-choice", action="store_true",
                    help="only the renders on which ST14's shadow threshold and low-frequency share were chosen")
    ap.add_argument("--cache", default="out/mitsuba-cache", help="folder for the cached renders")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=64)
    args = ap.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in methods if m not in PS_METHODS]
    if unknown:
        raise SystemExit(f"unknown method {unknown[0]!r}; choose from {', '.join(sorted(PS_METHODS))}")
    if args.st14_choice:
        return st14_choice()
    status = 0
    if not args.no_real:
        with tempfile.TemporaryDirectory() as tmp:
            status |= diligent_table(methods, args.root or default_root(), tmp)
    if not args.no_mitsuba:
        status |= mitsuba_table(methods, args.cache, args.size, args.spp)
    return status
