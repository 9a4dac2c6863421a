"""estimate_reflectance_scale: the albedo's scale to a reflectance, read from the images."""
import numpy as np

from facette.bench._mitsuba_scenes import render_scene
from facette.recon import ps_rank_trimmed, without_interreflections
from facette.recon._interreflect_scale import estimate_reflectance_scale


def test_the_scale_follows_the_images_and_lands_near_the_truth(tmp_path):
    # Mitsuba's relief in plaster (the images are radiance factors: the true scale is 1), then the
    # same images x 3.7 (relative intensities: the true scale 1 / 3.7)
    d = render_scene("relief", "plaster", size=64, spp=32, cache_dir=tmp_path)
    found = []
    for c in (1.0, 3.7):
        im = d["images"] * c
        first = ps_rank_trimmed(im, d["light_dirs"], mask=d["mask"])
        s, info = estimate_reflectance_scale(im, d["light_dirs"], first.normal, first.albedo, first.valid)
        assert 0 < s <= info["max_scale"] and info["identified"]
        found.append(s * c)
    assert abs(found[0] - found[1]) < 1e-3 * found[0]
    assert 0.7 < found[0] < 1.6, found


def test_a_convex_dome_gathers_nothing_and_keeps_its_images():
    y, x = np.mgrid[:40, :40] - 19.5
    inside = x * x + y * y < 18 ** 2
    z = np.sqrt(np.clip(18.0 ** 2 - x * x - y * y, 1, None))
    n = (np.dstack([x, -y, z]) / np.linalg.norm(np.dstack([x, -y, z]), axis=-1, keepdims=True)).astype(np.float32)
    L = np.array([[0, 0, 1.0], [0.5, 0, 0.866], [0, 0.5, 0.866], [-0.5, 0, 0.866], [0, -0.5, 0.866]])
    im = (3.0 * np.clip(np.einsum("md,hwd->mhw", L, n), 0, None) * inside).astype(np.float32)
    out, first, info = without_interreflections(im, L, inside, reflectance_scale="auto")
    assert not info["applied"] and out is im
    assert info["reflectance_scale"] > 0 and "scale_estimate" in info


def test_a_direct_light_render_does_not_tell_the_scale(tmp_path):
    # the relief with the direct light only (max_depth 2): its albedo does not grow with the light the
    # heights say it would gather, so the scale is not identified and "identified" removes nothing
    d = render_scene("relief", "plaster", size=64, spp=32, cache_dir=tmp_path, max_depth=2)
    im = d["images"] * 3.7
    first = ps_rank_trimmed(im, d["light_dirs"], mask=d["mask"])
    _, info = estimate_reflectance_scale(im, d["light_dirs"], first.normal, first.albedo, first.valid)
    assert not info["identified"] and info["costs"][0] <= 0
    out, _, removal = without_interreflections(im, d["light_dirs"], d["mask"], reflectance_scale="identified")
    assert out is im and not removal["applied"] and removal["scale_identified"] is False


def test_a_slope_that_falls_only_at_the_largest_scales_is_not_the_light_gathered():
    # facette's satin sphere on a plane renders no inter-reflections; its albedo grows a little with
    # the share the heights say it gathers, and only removals near the largest scale take that away
    # (values cut at the cap): not identified (EARLY_SHARE), though the slope starts above 0 and ends below
    from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions
    sc, L = sphere_on_plane(34, 46), thesis_light_directions()
    im = render(sc, L, "satin", noise=0.002, rng=np.random.default_rng(5)).astype(np.float32)
    first = ps_rank_trimmed(im, L, mask=sc.mask)
    _, info = estimate_reflectance_scale(im, L, first.normal, first.albedo, first.valid & sc.mask)
    slopes = info["costs"]
    assert slopes[0] > 0 and info["growth_kept"] <= 0.25          # the other two conditions hold
    assert not info["identified"]


def test_an_albedo_pattern_that_leans_with_the_gathered_share_is_not_the_light_gathered():
    # bench size's slab: local shading (no inter-reflections) with a smooth albedo pattern; its albedo
    # grows a little with the share the heights say it gathers and the removal takes that lean away,
    # but it does not follow the share cell by cell (GATHER_CORRELATION): not identified
    from facette.bench._large import relief_surface, _albedo
    from facette.recon.synthetic import thesis_light_directions
    from facette.recon._interreflect_scale import GATHER_CORRELATION
    rows, cols = np.arange(48), np.arange(64)
    _, n = relief_surface(rows, cols, 48)
    rho, L = _albedo(rows, cols, 48)[..., 1], thesis_light_directions()
    im = (rho / np.pi * np.clip(np.einsum("md,hwd->mhw", L, n), 0, None)).astype(np.float32)
    mask = np.ones(rho.shape, bool)
    first = ps_rank_trimmed(im, L, mask=mask)
    _, info = estimate_reflectance_scale(im, L, first.normal, first.albedo, first.valid)
    slopes = info["costs"]
    assert slopes[0] > 0 and info["growth_kept"] <= 0.25          # the slope tests alone pass it
    assert info["gather_correlation"] < GATHER_CORRELATION and not info["identified"]


def test_the_growth_is_read_on_the_albedo_its_lobe_modelled_when_given(tmp_path):
    # `diffuse`: a BRDF-aware fit's albedo (li_alternating's K_d). The Lambertian albedo itself gives
    # the Lambertian reading; an albedo that does not grow with the gathered share (all a lobe's doing)
    # is not identified, whatever the Lambertian albedo showed
    d = render_scene("relief", "plaster", size=64, spp=32, cache_dir=tmp_path)
    im = d["images"]
    first = ps_rank_trimmed(im, d["light_dirs"], mask=d["mask"])
    args = (im, d["light_dirs"], first.normal, first.albedo, first.valid)
    _, plain = estimate_reflectance_scale(*args)
    _, same = estimate_reflectance_scale(*args, diffuse=first.albedo * 2.0)      # the scale does not matter
    flat = np.where(first.valid[..., None], 0.5, np.nan).astype(np.float32)
    _, lobe = estimate_reflectance_scale(*args, diffuse=flat)
    assert plain["identified"] and same["identified"] and plain["diffuse_correlation"] is None
    assert abs(same["diffuse_correlation"] - plain["gather_correlation"]) < 0.05
    assert abs(same["costs"][0] - plain["costs"][0]) < 0.2 * plain["costs"][0]
    assert not lobe["identified"] and lobe["diffuse_correlation"] == 0.0 and abs(lobe["costs"][0]) < 1e-9
