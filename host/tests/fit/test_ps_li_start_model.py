"""li_alternating started from an earlier solve's model choice (`start_model`, `start_model_of`): the
inter-reflection decision's li run is not made twice on the hot path."""
import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from facette.bench._mitsuba_scenes import render_scene
from facette.fit import ps_li_alternating, start_model_of
from facette.fit._ps_li_pixels import Pixels
from facette.methods import photometric_stereo
from facette.recon.synthetic import angular_error_deg, render, sphere_on_plane, thesis_light_directions


@pytest.fixture(scope="module")
def sphere(tmp_path_factory):
    return render_scene("sphere", "paint_0.10", size=48, spp=16, cache_dir=tmp_path_factory.mktemp("mitsuba"))


def test_a_later_solve_takes_the_earlier_model_and_makes_no_choice(sphere, monkeypatch):
    d = sphere
    first = ps_li_alternating(d["images"], d["light_dirs"], mask=d["mask"])
    start = start_model_of(first)
    fit, choice = start
    assert choice["model"] == "lobe" and abs(fit["sigma"] - 0.10) < 0.03 and abs(fit["n_i"] - 1.30) < 0.06
    # at half the values li fits another n_i (the lobe's height is absolute): the choice carries
    # over, the numbers are warmed up again on these images
    own = ps_li_alternating(d["images"] * 0.5, d["light_dirs"], mask=d["mask"])
    monkeypatch.setattr(Pixels, "choose_model", lambda *a: pytest.fail("chose again"))
    again = ps_li_alternating(d["images"] * 0.5, d["light_dirs"], mask=d["mask"], start_model=start)
    mat, mat_own = again.info["materials"][0], own.info["materials"][0]
    assert mat["model_choice"]["made_on"].startswith("an earlier solve") and mat["diffuse"] == mat_own["diffuse"]
    assert abs(mat["sigma"] - mat_own["sigma"]) < 0.01 and abs(mat["n_i"] - mat_own["n_i"]) < 0.02
    assert abs(mat["n_i"] - fit["n_i"]) > 0.05           # not the earlier solve's number
    sel = binary_erosion(d["mask"])
    e_own, e_again = (angular_error_deg(r.normal, d["normals"])[sel].mean() for r in (own, again))
    assert e_again < e_own + 0.05, (e_own, e_again)


def test_no_start_model_from_several_materials_or_no_choice(sphere):
    d = sphere
    res = ps_li_alternating(d["images"], d["light_dirs"], mask=d["mask"])
    lam = dict(res.info["materials"][0], model_choice={"model": "lambertian", "why": "test"})
    res.info["materials"] = [lam]
    assert start_model_of(res)[1]["model"] == "lambertian"
    res.info["materials"] = [lam, lam]
    assert start_model_of(res) is None
    res.info["materials"] = [{k: v for k, v in lam.items() if k != "model_choice"}]
    assert start_model_of(res) is None


def test_a_matte_material_takes_least_squares_where_no_light_is_left_out():
    # a matte sphere on a plane, its values noisier than t_residual (as a concave wall's after the
    # gathered light is taken out: the path tracer's noise stays): least squares wherever the robust
    # start left no light out, not its trimmed solution, which drops direct light
    sc = sphere_on_plane(48, 48)
    lights = thesis_light_directions()
    im = render(sc, lights, "matte", noise=0.04, rng=np.random.default_rng(1))
    r = ps_li_alternating(im, lights, mask=sc.mask)
    assert r.info["materials"][0]["model_choice"]["model"] == "lambertian"
    ls = photometric_stereo(im, lights, method="woodham1980", mask=sc.mask)
    rt = photometric_stereo(im, lights, method="rank_trimmed", mask=sc.mask)
    clean = r.valid & ~(rt.shadow | rt.specular).any(-1) & (ls.residual >= 0.03)
    assert clean.sum() > 0.2 * r.valid.sum()
    np.testing.assert_allclose(r.normal[clean], ls.normal[clean])
    err = lambda n: angular_error_deg(n, sc.normals)[clean].mean()
    assert err(r.normal) < 0.85 * err(rt.normal), (err(r.normal), err(rt.normal))
