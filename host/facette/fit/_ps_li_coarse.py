"""Coarse-to-fine for `ps_li_alternating` on large images (its module doc): the inputs binned
f × f for the coarse alternation, and at full size each material's (σ, n_i) kept from the coarse
pass and a few steps per pixel from the upsampled coarse normal (`material_from_coarse`)."""
import time

import numpy as np

from facette._threads import run_blocks

from ._ps_li_pixels import angle_deg, join_blocks

FINE_START_DEG = 5.0       # the fine round starts from the initial normal where the coarse one is this far
FINE_STEP_TOL = 1e-3       # rad (0.06°): full-size steps stop below this (errors are ~1°)


def coarse_factor(n_valid, coarse_pixels, materials):
    """The binning factor f of the coarse pass (the smallest that brings the valid pixels below
    coarse_pixels), or None: small images, or several materials, run at full size."""
    if coarse_pixels and materials in (1, None) and n_valid > coarse_pixels:
        return int(np.ceil(np.sqrt(n_valid / coarse_pixels)))
    return None


def material_from_coarse(px, model, pix, mat, rounds_log, row0=0):
    """The full-size step of the one material (the pixels `pix` of a band from row `row0`, or of
    the whole image) with the `model` of the coarse pass (`_ps_li_bands.LiModel`): its (σ, n_i)
    kept, or, where the coarse pass found no lobe, the model choice made on full-size pixels of the
    sample. Updates `mat` and px.vm; returns (σ, n_i) or None."""
    st = px.settings
    cinfo = model.coarse_info
    cmat = cinfo["materials"][0] if cinfo.get("materials") else {"brdf_step": False}
    px.vm = cmat.get("volume_model", px.vm)
    if "model_choice" in cmat:     # made on the coarse images: say so at full size too
        mat["model_choice"] = dict(cmat["model_choice"], made_on="the coarse pass")
    if model.choice is not None:
        # binning smears a sharp highlight over its block, and the lobe no longer fits it:
        # a glossy sphere at 2144x1424 binned by 4 showed a 1.9 % gain (Lambertian), 67 % at
        # 536x356 unbinned. So "no lobe" was asked again of full-size pixels (the sample's).
        fit, choice = model.choice
        if choice["model"] == "lobe":
            px.vm = fit["volume_model"]
            mat["model_choice"] = dict(choice, made_on="full-size pixels (the coarse pass found no lobe)")
            x0 = (fit["sigma"], fit["n_i"])
            # the coarse normals are Lambertian ones: converge
            fine_round(px, model, pix, x0, st.iterations or st.fine_iterations, rounds_log, row0)
            return x0
        mat.update(brdf_step=False, note="coarse pass: " + cmat.get("note", "no BRDF step"))
        px.lambertian_material(pix)
        return (cmat["sigma"], cmat["n_i"]) if cmat.get("sigma") is not None else None
    x0 = (cmat["sigma"], cmat["n_i"])
    fine_round(px, model, pix, x0, st.fine_iterations, rounds_log, row0)
    return x0


def fine_round(px, model, pix, x0, steps, rounds_log, row0=0):
    """Full size after the coarse pass: (σ, n_i) kept, `steps` steps from the upsampled normal."""
    t_r, c_r = time.perf_counter(), time.process_time()
    sigma, n_i = x0
    up = upsample_normals(model.coarse_normal, px.shape, model.factor, row0).reshape(-1, 3)[px.idx]
    # at a silhouette the upsampled normal blends the object's rim with the table's, and a few
    # steps do not bring it back (the simulated 12 MP scan: a 3° ring round its sphere, heights
    # 0.45 mm off); where it is > FINE_START_DEG from the pixel's own initial normal, that is the start
    up = np.where((angle_deg(up, px.nrm0) > FINE_START_DEG)[:, None], px.nrm0, up)
    lobe, lam_ok, todo = px.split_levels(pix, sigma, n_i)
    change, mean_its = np.zeros(0), 0.0
    if todo.size:
        out = px.solve_from(todo, up[todo], sigma, n_i, steps, step_tol=FINE_STEP_TOL)
        rr = join_blocks(out)
        mean_its = float(np.average([getattr(p, "mean_iterations", p.iterations) for p in out],
                                    weights=[len(p.normals) for p in out]))
        change = angle_deg(rr.normals, up[todo])
        px.store(todo, rr)
    rounds_log.append({"material": 0, "round": "full size", "sigma": sigma, "n_i": n_i,
                       "pixels_refined": int(todo.size), "pixels_lambertian": int(lam_ok.sum()),
                       "pixels_initial_kept": int((~lam_ok & ~lobe).sum()),
                       "median_change_deg": float(np.median(change)) if change.size else 0.0,
                       "mean_change_deg": float(change.mean()) if change.size else 0.0,
                       "mean_iterations": mean_its,
                       "seconds": time.perf_counter() - t_r,
                       "cpu_seconds": time.process_time() - c_r})


def bin_inputs(images, light_dirs, mask, f, saturation):
    """Images (m, H, W, C), directions and mask binned by f × f blocks (H, W padded up).

    A binned value is the mean of the block's masked, finite (and, with `saturation`, unsaturated)
    values; NaN where fewer than half the block's pixels are such. The binned mask: at least half
    the block's pixels masked. Per-pixel directions: the block mean, renormalised."""
    m, h, w, c = images.shape
    hc, wc = -(-h // f), -(-w // f)

    from ._bin_jit import bin_images   # numba loads only when li_alternating runs

    msk = np.pad(mask, [(0, hc * f - h), (0, wc * f - w)])
    cmask = msk.reshape(hc, f, wc, f).sum((1, 3)) * 2 >= f * f
    out = bin_images(images, mask, f, saturation)
    if light_dirs.ndim == 2:
        dirs = light_dirs
    else:
        ld = np.pad(light_dirs, [(0, hc * f - h), (0, wc * f - w), (0, 0), (0, 0)], mode="edge")
        dirs = ld.reshape(hc, f, wc, f, m, 3).mean((1, 3))
        dirs = (dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)).astype(np.float32)
    return out, dirs, cmask


def upsample_normals(coarse, shape, f, row0=0):
    """(H, W, 3) unit normals bilinearly interpolated from the (hc, wc, 3) coarse normals (cell
    centres); coarse pixels without a normal take their nearest valid neighbour's first. row0: the
    first of the H rows in the whole image (a band's), whose blocks the coarse cells are."""
    from scipy.ndimage import distance_transform_edt, map_coordinates
    valid = np.linalg.norm(coarse, axis=-1) > 0.5
    if not valid.any():
        return np.zeros(shape + (3,), np.float32)
    if not valid.all():
        _, (iy, ix) = distance_transform_edt(~valid, return_indices=True)
        coarse = coarse[iy, ix]
    h, w = shape
    yy = (np.arange(row0, row0 + h, dtype=np.float32) + 0.5) / f - 0.5
    xx = (np.arange(w, dtype=np.float32) + 0.5) / f - 0.5
    gy, gx = np.meshgrid(yy, xx, indexing="ij")
    out = np.empty((h, w, 3), np.float32)

    def channel(k):        # scipy's interpolation lets the GIL go: the three on threads
        out[..., k] = map_coordinates(coarse[..., k], [gy, gx], order=1, mode="nearest")

    run_blocks(channel, range(3))
    ln = np.linalg.norm(out, axis=-1, keepdims=True)
    return np.where(ln > 1e-6, out / np.maximum(ln, 1e-6), np.float32([0, 0, 1])).astype(np.float32)
