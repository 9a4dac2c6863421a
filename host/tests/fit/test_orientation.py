"""The hemisphere search for a start (facette.fit._orientation) and the metal's lobe it serves."""
import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from facette.bench._mitsuba_scenes import render_scene
from facette.brdf import li_shading_terms
from facette.brdf._fresnel import check_n_i
from facette.fit import ps_li_alternating
from facette.fit._orientation import hemisphere, search_start
from facette.methods import photometric_stereo
from facette.recon.synthetic import angular_error_deg, thesis_light_directions


def _metal_values(normals, lights, sigma=0.2, n_i=40.0):
    """A bare metal's values (no diffuse part) by our own model: the search's own case."""
    a, _ = li_shading_terms(normals, lights, sigma, n_i, volume_model="lambert")
    return a


def test_the_search_finds_a_metal_normal_from_a_start_that_says_nothing():
    lights = thesis_light_directions()
    rng = np.random.default_rng(0)
    truth = hemisphere(5000)[rng.choice(5000, 1000, replace=False)]
    truth = truth[truth[:, 2] > 0.5]
    e = _metal_values(truth, lights)
    seen = e.max(1) > 1e-3 * e.max()                     # a pixel no light reaches says nothing
    flat = np.tile(np.float32([0, 0, 1]), (len(truth), 1))
    starts, better = search_start(e, lights, np.ones(e.shape, bool), 0.2, 40.0, "lambert", flat)
    err = np.degrees(np.arccos(np.clip(np.sum(starts * truth, 1), -1, 1)))
    assert seen.sum() > 100
    assert better[seen].mean() > 0.9
    assert np.median(err[seen & better]) < 2.5           # the candidates are ~2.3 deg apart
    # where the given normal already explains the pixel, it is kept and not searched
    starts, better = search_start(e, lights, np.ones(e.shape, bool), 0.2, 40.0, "lambert", truth)
    assert not better.any() and np.array_equal(starts, truth)


def test_the_search_leaves_out_values_that_are_not_usable():
    lights = thesis_light_directions()
    truth = np.float32([[0.3, -0.2, 0.93]])
    truth /= np.linalg.norm(truth)
    e = _metal_values(truth, lights)
    bright = int(np.argmax(e[0]))
    spoiled = e.copy()
    spoiled[0, bright] = np.nan                           # a NaN where it is marked unusable
    ok = np.ones(e.shape, bool)
    ok[0, bright] = False
    flat = np.float32([[0, 0, 1]])
    st_ok, _ = search_start(e, lights, np.ones(e.shape, bool), 0.2, 40.0, "lambert", flat)
    st_nan, _ = search_start(spoiled, lights, ok, 0.2, 40.0, "lambert", flat)
    assert np.all(np.isfinite(st_nan))
    assert np.degrees(np.arccos(np.clip(st_ok[0] @ truth[0], -1, 1))) < 2.5


def test_an_index_above_the_dielectrics_stands_for_a_metal_up_to_100():
    assert check_n_i(40.0) == 40.0
    with pytest.raises(ValueError, match="1, 100"):
        check_n_i(101.0)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("mitsuba")


@pytest.mark.parametrize("material", ["aluminium", "metallic_paint"])
def test_a_metal_rendered_by_mitsuba_gets_a_metal_lobe_and_normals_far_better_than_lambert(cache, material):
    # Mitsuba's roughconductor (Al, α 0.3) and a copper/diffuse blend (α 0.2): not our BRDF code
    d = render_scene("sphere", material, size=48, spp=8, cache_dir=cache)
    r = ps_li_alternating(d["images"], d["light_dirs"], mask=d["mask"])
    mat = r.info["materials"][0]
    assert mat["diffuse"] == "lambert" and mat["n_i"] > 2.5, mat["model_choice"]
    true_alpha = {"aluminium": 0.3, "metallic_paint": 0.2}[material]
    assert abs(mat["sigma"] - true_alpha) < 0.05 * true_alpha / 0.3 + 0.02, mat
    seen = binary_erosion(d["mask"]) & r.valid
    assert seen.sum() > 0.5 * binary_erosion(d["mask"]).sum()
    ls = photometric_stereo(d["images"], d["light_dirs"], method="woodham1980", options={"mask": d["mask"]})
    ours = np.mean(angular_error_deg(r.normal, d["normals"], seen))
    least_squares = np.mean(angular_error_deg(ls.normal, d["normals"], seen))
    assert ours < 3.0 and ours < 0.2 * least_squares, (ours, least_squares)
