"""Calibration targets on the simulated rig's table (the Spectralon, the spheres, the empty
table, the lens cap), rendered with the simulator's own renderer and true LEDs.

facette.sim renders a `Scene` (height field, normals, mask, albedo map, one BRDF) under
its LEDs (`facette.sim.render.radiance_per_led`), and its camera integrates
`SimCamera.radiance` (m, H, W, 3) e-/(mA·µs). A target is shown by building its
Scene on a finer grid (anti-aliasing), rendering it with the simulator's own
renderer and true LEDs, blurring by the lens PSF and binning to the camera grid,
then handing that to the camera.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from facette.calib.targets import channel_reflectance, pixel_grid_mm, rgb_triplet
from facette.sim.render import radiance_per_led
from facette.sim.scene import Scene

__all__ = ["SIM_TARGETS", "TARGET_FAULTS", "target_scene", "render_target", "show_target", "restore_scene"]

SIM_TARGETS = ("spectralon", "mirror_sphere", "matte_sphere", "none", "lens_cap")


def target_scene(kind, shape, pixel_pitch_mm, center_mm=(0.0, 0.0), radius_mm=None,
                 reflectance=None, supersample=1):
    """The Scene of a calibration target on the simulated rig's table.

    kind : "spectralon" (flat certified white filling the field, Lambert),
        "mirror_sphere" (chrome ball: Cook–Torrance, K_d = 0, σ = 0.02, n_i = 2.5, on a
        grey card), "matte_sphere" (Lambert sphere on a dark card), "none" (the empty
        table), "lens_cap" (nothing reaches the sensor).
    shape, pixel_pitch_mm : the camera's (half-size) grid; the scene is `supersample`
        times finer. center_mm, radius_mm : the sphere (default radius 40 % of the
        field's height). reflectance : (3,) override of the target's reflectance.
    """
    if kind not in SIM_TARGETS:
        raise ValueError(f"unknown target {kind!r}; choose one of {SIM_TARGETS}")
    ss = int(supersample)
    h, w = int(shape[0]) * ss, int(shape[1]) * ss
    pitch = pixel_pitch_mm / ss
    x, y = pixel_grid_mm((h, w), pitch)
    height = np.zeros((h, w))
    normals = np.zeros((h, w, 3))
    normals[..., 2] = 1.0
    mask = np.zeros((h, w), bool)
    lambert = {"model": "lambert", "params": {}}
    if kind in ("spectralon", "lens_cap"):
        rho = channel_reflectance() if reflectance is None else rgb_triplet(reflectance)
        albedo = np.broadcast_to(rho * (kind == "spectralon"), (h, w, 3)).copy()
        mask[:] = kind == "spectralon"
        return Scene(height, normals, mask, albedo, pitch, lambert, name=f"target:{kind}")
    if kind == "none":
        albedo = np.broadcast_to([0.04, 0.04, 0.045], (h, w, 3)).copy()
        return Scene(height, normals, mask, albedo, pitch, lambert, name="target:none")
    r = (0.4 * shape[0] * pixel_pitch_mm) if radius_mm is None else float(radius_mm)
    cx, cy = center_mm
    d2 = (x - cx) ** 2 + (y - cy) ** 2
    mask = d2 < r * r
    # the sphere sits on the table: its centre is r above it
    height = np.where(mask, r + np.sqrt(np.clip(r * r - d2, 0, None)), 0.0)
    # analytic normals: the table stays flat up to the silhouette (a finite-difference
    # gradient would tilt the ring of table pixels next to the sphere's equator)
    nz = np.sqrt(np.clip(1 - d2 / (r * r), 0, None))
    normals[mask] = np.stack([(x - cx) / r, (y - cy) / r, nz], -1)[mask]
    if kind == "mirror_sphere":
        albedo = np.where(mask[..., None], 0.0, 0.5)
        albedo = np.broadcast_to(albedo, (h, w, 3)).copy()
        brdf = {"model": "cook_torrance", "params": {"sigma": 0.02, "n_i": 2.5}}
        return Scene(height, normals, mask, albedo, pitch, brdf, name="target:mirror_sphere")
    rho = np.array([0.9, 0.9, 0.9]) if reflectance is None else rgb_triplet(reflectance)
    albedo = np.where(mask[..., None], rho, 0.05)
    return Scene(height, normals, mask, np.broadcast_to(albedo, (h, w, 3)).copy(), pitch, lambert,
                 name="target:matte_sphere")


def _sim_scale(sim):
    """The simulator's electrons per mA·s, recovered from the radiance it rendered."""
    base = radiance_per_led(sim.scene, sim.leds, 1.0, shadows=False)
    ok = base > 1e-12 * max(base.max(), 1e-300)
    if not ok.any():
        return 20.0
    return float(np.median(sim.camera.radiance[ok] / base[ok]))


def render_target(sim, kind, supersample=4, psf_px=0.7, **scene_kw):
    """Electron maps (m, H, W, 3) e-/(mA·µs) of a target under the simulator's true LEDs."""
    h, w = sim.camera.radiance.shape[1:3]
    ss = int(supersample) if kind in ("mirror_sphere", "matte_sphere") else 1
    scene = target_scene(kind, (h, w), sim.scene.pixel_pitch_mm, supersample=ss, **scene_kw)
    if not hasattr(sim, "_calib_scale"):
        sim._calib_scale = _sim_scale(sim)
    # no cast shadows: a sphere would shadow its own rim on the coarse height field
    fine = radiance_per_led(scene, sim.leds, sim._calib_scale, shadows=False)
    if ss > 1 or psf_px:
        sigma = (0, psf_px * ss, psf_px * ss, 0) if psf_px else 0
        if psf_px:
            fine = ndimage.gaussian_filter(fine, sigma, mode="nearest")
        fine = fine.reshape(len(fine), h, ss, w, ss, 3).mean(axis=(2, 4))
    return fine, scene


TARGET_FAULTS = ("missing", "overexposed")


def show_target(sim, kind, fault=None, **kw):
    """Put a target under the simulated camera: its next frames see it.

    `sim` is a facette.sim.SimulatedRig (``rig.sim``). Returns the target's Scene
    (fine grid). Scene keywords (center_mm, radius_mm, reflectance) pass through.
    fault : None, or a demonstration of a failed placement: "missing" shows the empty
        table instead, "overexposed" the target 300× too bright.
    """
    if fault not in (None, *TARGET_FAULTS):
        raise ValueError(f"unknown target fault {fault!r}; choose one of {', '.join(TARGET_FAULTS)}")
    if getattr(sim, "banded", False):
        raise ValueError("calibration targets are shown on a simulated rig rendered whole; this one renders "
                         "in bands (a large --raw-size): calibrate at a smaller size")
    radiance, scene = render_target(sim, "none" if fault == "missing" else kind, **kw)
    if not hasattr(sim, "_calib_original"):
        sim._calib_original = sim.camera.radiance
    sim.camera.radiance = radiance * 300.0 if fault == "overexposed" else radiance
    return scene


def restore_scene(sim):
    """Give the simulated camera back the rig's own object."""
    if hasattr(sim, "_calib_original"):
        sim.camera.radiance = sim._calib_original
