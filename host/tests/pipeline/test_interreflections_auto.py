"""`process`'s default for inter-reflections ("auto"): removed on a reflectance-calibrated scan read
whole; on relative images removed where the images tell the albedo's scale (the path-traced relief
does; a direct-light render and a satin sphere on a plane, which gather nothing, do not: their
normals are the images' own); left in with a note that says why for the simulator and --memory
(pipeline._interreflections)."""
import json

import numpy as np
import pytest

from facette.errors import InsufficientData, NotAReflectance
from facette.pipeline import process
from facette.recon._interreflect_scale import DIFFUSE_CORRELATION, GATHER_CORRELATION
from facette.recon.synthetic import angular_error_deg

from mitsuba_scan import SCALE, calibrated_scan as _scan, render
from satin_scene import satin_sphere_on_a_plane


@pytest.fixture(scope="module")
def relief():
    """A Mitsuba relief in plaster (64 px, 32 spp): a concave object that gathers its own light."""
    return render("relief", "plaster")


@pytest.fixture(scope="module")
def direct_relief():
    """The same relief with the direct light only (max_depth 2): no light gathered in its images."""
    return render("relief", "plaster", max_depth=2)


def test_removed_by_default_on_a_calibrated_scan(tmp_path, relief):
    scan = _scan(tmp_path / "scan", relief)
    res = process(scan, outputs=["normals"], out_dir=tmp_path / "out", method="woodham1980", mask=relief["mask"])
    left = process(scan, outputs=["normals"], method="woodham1980", mask=relief["mask"], interreflections=False)
    assert res.inputs.reflectance and res.interreflections["applied"]
    assert any(n.startswith("inter-reflections removed") for n in res.notes)
    assert left.interreflections is None and not any("inter-reflections" in n for n in left.notes)
    sel = relief["mask"] & res.mask & left.mask
    err = lambda r: angular_error_deg(r.normals, relief["normals"])[sel].mean()
    assert err(res) < 0.85 * err(left), (err(res), err(left))
    assert json.loads((tmp_path / "out" / "process.json").read_text())["options"]["interreflections"] == "auto"


def test_relative_images_lose_the_light_where_the_images_tell_its_scale(tmp_path, relief, direct_relief):
    # without the Spectralon step the images are relative: the path-traced relief gathers its own
    # light and li_alternating's diffuse albedo grows with it (the scale is identified): removed
    res = process(_scan(tmp_path / "relative0", relief, scale=None), outputs=["normals"], method="woodham1980")
    left = process(_scan(tmp_path / "relative1", relief, scale=None), outputs=["normals"], method="woodham1980",
                   interreflections=False)
    assert not res.inputs.reflectance and res.interreflections["applied"]
    found = res.interreflections["identified_on"]
    assert found["diffuse_correlation"] >= DIFFUSE_CORRELATION and found["growth_kept"] <= 0.25
    assert any("found by 'auto'" in n for n in res.notes)
    sel = relief["mask"] & res.mask & left.mask
    err = lambda r: angular_error_deg(r.normals, relief["normals"])[sel].mean()
    assert err(res) < 0.85 * err(left), (err(res), err(left))
    # the same relief with the direct light only: nothing gathered in the images, and the note says so
    auto = process(_scan(tmp_path / "direct0", direct_relief, scale=None), outputs=["normals"], method="woodham1980")
    plain = process(_scan(tmp_path / "direct1", direct_relief, scale=None), outputs=["normals"], method="woodham1980",
                    interreflections=False)
    assert not auto.interreflections["applied"] and not auto.interreflections["scale_identified"]
    assert any("left in (interreflections 'auto'): the images do not tell the albedo's scale" in n
               for n in auto.notes)
    np.testing.assert_array_equal(auto.normals, plain.normals)


def test_a_satin_sphere_on_a_plane_keeps_its_normals(tmp_path):
    # its lobe's share grows toward the rim as the share the plane would send does: the Lambertian
    # albedo follows the gathered share (the rule before the lobe was modelled identified it, and the
    # removal took its normals 0.54 -> 1.57 deg); li_alternating's diffuse albedo does not
    folder = satin_sphere_on_a_plane(tmp_path / "objPNG")
    auto = process(folder, outputs=["normals"], method="woodham1980")
    plain = process(folder, outputs=["normals"], method="woodham1980", interreflections=False)
    est = auto.interreflections["scale_estimate"]
    assert not auto.interreflections["applied"] and not est["identified"]
    assert est["gather_correlation"] >= GATHER_CORRELATION > est["diffuse_correlation"]
    assert any("its lobe modelled, does not follow" in n for n in auto.notes)
    np.testing.assert_array_equal(auto.normals, plain.normals)


def test_the_default_method_removes_where_identified(tmp_path, relief, direct_relief):
    res = process(_scan(tmp_path / "relative", relief, scale=None), outputs=["normals"])
    left = process(_scan(tmp_path / "left", relief, scale=None), outputs=["normals"], interreflections=False)
    assert res.ps.method == "li_alternating" and res.interreflections["applied"]
    # the decision's li_alternating model choice is the later solves' (not made twice)
    assert res.interreflections["model_reused"]
    assert res.ps.info["materials"][0]["model_choice"]["made_on"].startswith("an earlier solve")
    sel = relief["mask"] & res.mask & left.mask
    err = lambda r: angular_error_deg(r.normals, relief["normals"])[sel].mean()
    assert err(res) < 0.9 * err(left), (err(res), err(left))
    direct = process(_scan(tmp_path / "direct", direct_relief, scale=None), outputs=["normals"])
    assert direct.interreflections["scale_identified"] is False and direct.interreflections["cpu_seconds"] >= 0


def test_left_in_with_the_reason_elsewhere(tmp_path, relief, monkeypatch, force_bands):
    # the rig simulator renders none (its truth carries the sensor model)
    sim = process(_scan(tmp_path / "sim", relief, truth={"sensor": np.zeros(1)}), outputs=["normals"],
                  method="woodham1980")
    assert sim.interreflections is None and any("the simulator renders none" in n for n in sim.notes)
    # a budget whose one band holds the capture: read whole, removed as without --memory
    one = process(_scan(tmp_path / "one", relief), outputs=["normals"], method="woodham1980", memory="1GB")
    assert one.interreflections is not None and any("fits one band" in n for n in one.notes)
    # --memory reads the images by bands (a band shorter than the image): left in by default
    force_bands(16)
    banded = process(_scan(tmp_path / "banded", relief), outputs=["normals"], method="woodham1980", memory="1GB")
    assert banded.interreflections is None and any("--memory reads the images by bands" in n for n in banded.notes)


def test_relative_images_have_their_scale_estimated_when_asked(tmp_path, relief):
    # relative images (x 4 here, the intensities divided out) with --interreflections: the albedo's
    # scale to a reflectance is estimated from them, and the removal brings the normals closer
    res = process(_scan(tmp_path / "relative", relief, scale=None), outputs=["normals"], method="woodham1980",
                  interreflections=True)
    left = process(_scan(tmp_path / "relative2", relief, scale=None), outputs=["normals"], method="woodham1980",
                   interreflections=False)
    assert not res.inputs.reflectance and res.interreflections["applied"]
    assert 0.7 < res.interreflections["reflectance_scale"] * SCALE < 1.6     # the truth: 1 / 4
    assert any("scale to a reflectance estimated from the images" in n for n in res.notes)
    sel = relief["mask"] & res.mask & left.mask
    err = lambda r: angular_error_deg(r.normals, relief["normals"])[sel].mean()
    assert err(res) < 0.9 * err(left), (err(res), err(left))

def test_a_calibration_gone_wrong_is_said_not_fatal_by_default(tmp_path, relief):
    # images 3x too bright for the scale written: the albedo is no reflectance (p99 above 1)
    scan = _scan(tmp_path / "bright", relief, scale=SCALE / 3)
    res = process(scan, outputs=["normals"], method="woodham1980")
    assert res.interreflections is None
    assert any("left in (interreflections 'auto'): removing inter-reflections needs the albedo as a reflectance"
               in n for n in res.notes)
    with pytest.raises(NotAReflectance, match="needs the albedo as a reflectance") as exc:
        process(scan, outputs=["normals"], method="woodham1980", interreflections=True)
    assert isinstance(exc.value, InsufficientData) and exc.value.exit_code == 3
    # the default method too: the refusal comes before any solve, and "auto" goes on without
    res = process(scan, outputs=["normals"])
    assert res.interreflections is None and res.ps.method == "li_alternating"
