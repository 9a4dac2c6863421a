"""`facette bench gltf`: what a glTF viewer (three.js, headless Chromium) shows of model.glb, at
lights the fit never saw, before (one material: the albedo, one roughness from the BRDF fit) and
after (the relighting model's per-pixel K_d, F0 and roughness maps, pipeline._gltf_maps).

For each capture every k-th light is held out, the rest given to `process --outputs
gltf,brdf,samples,relight`; both .glb files are drawn by three.js under each held-out light
(directional, no shadow map, no environment) and compared with the photograph in 8-bit display values
over the object's pixels (PSNR over every pixel and channel, as `bench relight`), beside the
relighting model's own display (normals, maps, cast shadows, residual: what the report's viewer
draws). "glb vs physics": the mean |8-bit difference| between three.js's picture of the new .glb
and the model's physics it was fitted to (no cast shadows, no residual): what the glTF
encoding itself costs. Times: the model's fit and the .glb's writing (wall, this machine's load).

Captures: a rendered sphere on a plane whose left half is a satin orange and right half a matte
blue (48 lights, every 6th held out); with --root (default ../shared/data beside the repository)
DiLiGenT's 8-bit crops cat and pot2 (96 lights, every 8th held out).

Usage: facette bench gltf [--root DIR] [--synthetic-only] [--method NAME] [--out DIR]
"""
import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import facette
from facette.bench._three import three_view
from facette.io.diligent import read_diligent, write_diligent
from facette.io.gltf import write_glb
from facette.pipeline import process
from facette.pipeline._exports import gltf_inputs, gltf_material
from facette.recon import srgb_encode
from facette.recon._relight_model import physical_basis
from facette.recon.synthetic import render, sphere_on_plane


def _two_materials(h=128, w=160, m=48):
    rng = np.random.default_rng(7)
    d = rng.normal(size=(m, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.9
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    sc = sphere_on_plane(h, w, radius=0.3 * h)
    left = (np.arange(w) < w // 2)[None, None, :, None]
    imgs = np.where(left, render(sc, d, "satin", albedo=(0.7, 0.45, 0.2)), render(sc, d, "matte",
                                                                                albedo=(0.2, 0.35, 0.7)))
    return "two materials (render)", imgs, d, sc.mask, 6


def _diligent(root, name):
    d = read_diligent(Path(root) / "diligent_crop8" / f"{name}PNG")
    return f"DiLiGenT {name} (8-bit crop)", np.asarray(d.images, np.float32), d.light_dirs, d.mask, 8


def _psnr(a, b):
    mse = float(np.mean((np.asarray(a, float) - np.asarray(b, float)) ** 2))
    return 10 * np.log10(255.0 ** 2 / mse) if mse > 0 else float("inf")


def _before_glb(res, path):
    """model.glb as facette wrote it before the maps: the same run without its relighting model."""
    old = replace(res, relight_model=None)
    material, _ = gltf_material(old)
    kwargs, _ = gltf_inputs(old, old.options.get("mesh_step", 1), material)
    write_glb(path, **kwargs)
    return material


def _case(label, images, dirs, mask, k, work, method):
    m = len(dirs)
    held = np.arange(k - 1, m, k)
    fit = np.setdiff1d(np.arange(m), held)
    scale = 60000.0 / float(np.nanmax(images[fit][:, mask]))
    folder = work / "capture"
    write_diligent(folder, np.clip(np.round(images[fit] * scale), 0, 65535).astype(np.uint16), dirs[fit],
                   mask=mask)
    t0 = time.perf_counter()
    res = process(folder, outputs=["gltf", "brdf", "samples", "relight"], out_dir=work / "out", method=method,
                  shadows="off")
    wall = time.perf_counter() - t0
    model = res.relight_model
    before = _before_glb(res, work / "before.glb")
    after_scale = float(np.mean(gltf_material(res)[0]["scale"]))
    white = model.white
    obj = model.mask
    h, w = obj.shape
    # the photographs in the fitted images' unit, shown as the model shows them (display white = its white)
    shown = [np.round(255 * srgb_encode(np.clip(images[j] * scale / 65535.0 / white, 0, 1))) for j in held]
    rows = {k: [] for k in ("before", "after", "model", "phys")}
    # before: base colour = albedo × scale, the albedo a reflectance (π radiance / irradiance): intensity
    # 1 / (scale white) shows albedo (n·l) / white; after: base colour = c_d × scale in display units
    for name, glb, intensity in (("before", work / "before.glb", 1.0 / (float(np.mean(before["scale"])) * white)),
                                 ("after", work / "out" / "model.glb", np.pi / after_scale)):
        with three_view(glb, w, h, res.inputs.pixel_pitch_mm) as (draw, materials):
            for j, photo in zip(held, shown):
                pic = draw(dirs[j], intensity)
                rows[name].append(_psnr(pic[obj], photo[obj]))
                if name == "after":
                    b = physical_basis(model.normals, dirs[j][None] / np.linalg.norm(dirs[j]), model.shininess)[0]
                    phys = model.rho * b[..., 0:1] + model.spec * b[..., 1:2] + model.amb * b[..., 2:3]
                    want = np.round(255 * srgb_encode(np.clip(phys, 0, 1)))
                    rows["phys"].append(float(np.abs(pic[obj].astype(float) - want[obj]).mean()))
                    rows["model"].append(_psnr(np.round(255 * model.display(dirs[j]))[obj], photo[obj]))
    size = {"before": (work / "before.glb").stat().st_size, "after": (work / "out" / "model.glb").stat().st_size}
    print(f"{label:30s} {w}x{h}, {len(fit)} fitted, {len(held)} held out; three.js: {', '.join(sorted(set(materials)))}")
    print(f"  held-out PSNR (dB, median / mean): before {np.median(rows['before']):6.2f} / {np.mean(rows['before']):6.2f}"
          f"   after {np.median(rows['after']):6.2f} / {np.mean(rows['after']):6.2f}"
          f"   model's own display {np.median(rows['model']):6.2f} / {np.mean(rows['model']):6.2f}")
    print(f"  glb vs physics: mean |diff| {np.median(rows['phys']):.2f} levels (median over lights);"
          f" glb {size['before'] / 1e6:.2f} -> {size['after'] / 1e6:.2f} MB")
    print(f"  times (s, wall): process {wall:.1f} (relight model {res.timings.get('relight_model', 0):.1f}, "
          f"brdf fit {res.timings.get('fit', 0):.1f}, write glb {res.timings.get('write_gltf', 0):.2f})")
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(prog="facette bench gltf", description=__doc__.splitlines()[0])
    p.add_argument("--root", default=str(Path(facette.__file__).resolve().parents[2].parent / "shared" / "data"))
    p.add_argument("--synthetic-only", action="store_true")
    p.add_argument("--method", default="woodham1980", help="photometric stereo (default woodham1980: fast)")
    p.add_argument("--out", help="keep the files here (default: a temporary folder)")
    a = p.parse_args(argv)
    cases = [_two_materials]
    if not a.synthetic_only:
        if (Path(a.root) / "diligent_crop8").is_dir():
            cases += [lambda: _diligent(a.root, "cat"), lambda: _diligent(a.root, "pot2")]
        else:
            print(f"no {Path(a.root) / 'diligent_crop8'}: the real captures are skipped (--root DIR)")
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(a.out) if a.out else Path(tmp)
        for i, make in enumerate(cases):
            label, images, dirs, mask, k = make()
            work = base / f"case{i}"
            work.mkdir(parents=True, exist_ok=True)
            _case(label, images, np.asarray(dirs, float), np.asarray(mask, bool), k, work, a.method)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
