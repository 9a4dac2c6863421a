"""`facette bench relight` (facette.bench.relight) on a rendered matte sphere: every method
predicts held-out lights, and the raking-light count tells the polynomial bases from the
physically based relighting."""
import numpy as np

from facette.bench.relight import METHODS, evaluate, main, raking_lights
from facette.io.diligent import write_diligent
from facette.recon.synthetic import render, sphere_on_plane


def dome(m, seed):
    """m light directions spread over the upper hemisphere, within 60° of the axis."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(m, 3))
    d[:, 2] = np.abs(d[:, 2]) + 1.5
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_raking_lights_are_75_degrees_from_the_axis_all_around():
    d = raking_lights()
    np.testing.assert_allclose(np.degrees(np.arccos(d[:, 2])), 75.0)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    assert np.allclose(d[:, :2].sum(axis=0), 0, atol=1e-12)


def test_held_out_lights_are_predicted_and_only_the_bases_go_negative_at_75_degrees(tmp_path):
    lights = dome(24, seed=3)
    sc = sphere_on_plane(48, 56, radius=18)
    imgs = render(sc, lights, "matte", albedo=(0.8, 0.7, 0.6), cast_shadows=False).astype(np.float32)
    mask = sc.sphere & np.all(sc.normals @ lights.T > 0.05, axis=-1)   # lit by every light
    scores, peak = evaluate(imgs, lights, mask, [np.arange(3, 24, 4)], tmp_path)
    assert peak > 0
    for name in METHODS:
        assert scores[name].sq, f"{name}: {scores[name].why}"
        assert np.isfinite(scores[name].rel_rms())
    # a Lambertian sphere lit everywhere: Lambert's law with the photometric-stereo albedo is exact
    assert scores["Lambert (PS)"].rel_rms() < 0.02
    assert scores["facette PB+gain"].rel_rms() < 0.05
    for name in ("Lambert (PS)", "facette PB", "facette PB+gain"):
        assert max(scores[name].neg) == 0
    assert max(scores["HSH 3"].neg) > 0.01


def test_main_without_data_says_so(tmp_path, capsys):
    assert main(["--root", str(tmp_path)]) == 0
    assert "no DiLiGenT data" in capsys.readouterr().out


def test_main_on_a_diligent_style_folder(tmp_path, capsys):
    lights = dome(16, seed=2)
    sc = sphere_on_plane(32, 40, radius=12)
    imgs = render(sc, lights, "matte", albedo=(0.8, 0.8, 0.8), cast_shadows=False)
    write_diligent(tmp_path / "diligent" / "ballPNG", np.round(imgs / imgs.max() * 60000).astype(np.uint16),
                   lights, mask=sc.sphere)
    assert main(["--root", str(tmp_path), "--diligent", "ballPNG", "--pi", ""]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in METHODS)
