"""`facette bench relight` (facette.bench.relight) on rendered captures: every method predicts
held-out lights in 8-bit display values, the relighting model beats HSH 3 and never goes
negative at raking light, the captures it writes as a dome user's read back."""
import numpy as np

from facette.bench._relight_data import Capture, hold_every, make_jpeg_capture
from facette.bench._relight_methods import METHODS
from facette.bench.relight import main, psnr8, raking_lights, score, ssim8
from facette.io.diligent import write_diligent
from facette.recon import srgb_encode
from facette.recon.synthetic import render, sphere_on_plane


def dome(m, seed):
    """m light directions spread over the upper hemisphere, within 60° of the axis."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(m, 3))
    d[:, 2] = np.abs(d[:, 2]) + 1.5
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _capture(m=36, seed=3, material="satin"):
    lights = dome(m, seed)
    sc = sphere_on_plane(40, 48, radius=14)
    lin = render(sc, lights, material, albedo=(0.8, 0.6, 0.4)).astype(np.float32)
    lin /= np.percentile(lin, 99.9)
    return Capture("sphere", "render", srgb_encode(np.clip(lin, 0, 1)).astype(np.float32), lin, lights,
                   sc.mask, hold_every(m, 6))


def test_raking_lights_are_75_degrees_from_the_axis_all_around():
    d = raking_lights()
    np.testing.assert_allclose(np.degrees(np.arccos(d[:, 2])), 75.0)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    assert np.allclose(d[:, :2].sum(axis=0), 0, atol=1e-12)


def test_scores_in_8_bit_display_values():
    a = np.full((8, 8, 3), 100.0)
    mask = np.ones((8, 8), bool)
    assert psnr8(a + 1, a, mask) == 10 * np.log10(255.0 ** 2)
    assert ssim8(a, a, mask) == 1.0
    assert ssim8(a + np.arange(8)[:, None, None] * 9, a, mask) < 1.0


def test_every_method_predicts_and_the_model_beats_hsh3_without_going_negative(tmp_path):
    cap = _capture()
    names = [n for n in METHODS if "before" not in n]
    rows = score(cap, names, tmp_path)
    for name in names:
        assert "psnr" in rows[name], f"{name}: {rows[name].get('why')}"
        assert np.isfinite(rows[name]["psnr"]) and 0 < rows[name]["ssim"] <= 1
    assert rows["facette model"]["psnr"] > rows["HSH 3"]["psnr"] + 2.0, rows
    assert rows["facette model"]["neg"] == 0 and rows["facette (no shadows)"]["neg"] == 0
    assert rows["HSH 3"]["neg"] > 1.0          # the polynomial goes negative at 75°


def test_jpeg_capture_reads_back_as_written(tmp_path):
    cap = _capture(m=12)
    back = make_jpeg_capture(cap, tmp_path / "jpeg", k=6)
    assert back.srgb8 and back.shown.shape == cap.shown.shape
    np.testing.assert_allclose(back.dirs, cap.dirs, atol=1e-8)
    err = np.abs(back.shown - cap.shown)[:, cap.mask]
    assert err.mean() < 3 / 255                # JPEG quality 90 of smooth renders


def test_main_without_data_says_so(tmp_path, capsys):
    assert main(["--root", str(tmp_path)]) == 0
    assert "no data under" in capsys.readouterr().out


def test_main_on_a_diligent_style_folder(tmp_path, capsys):
    lights = dome(16, seed=2)
    sc = sphere_on_plane(32, 40, radius=12)
    imgs = render(sc, lights, "matte", albedo=(0.8, 0.8, 0.8), cast_shadows=False)
    write_diligent(tmp_path / "diligent" / "ballPNG", np.round(imgs / imgs.max() * 60000).astype(np.uint16),
                   lights, mask=sc.sphere)
    assert main(["--root", str(tmp_path), "--diligent", "ballPNG", "--groups", "diligent,jpeg",
                 "--methods", "HSH 3,facette model", "--no-before"]) == 0
    out = capsys.readouterr().out
    assert "ballPNG" in out and "ballPNG.jpg" in out and "facette model" in out and "vs HSH 3" in out


def test_large_section_reports_time_and_peak_memory(tmp_path, capsys):
    from facette.bench._relight_large import run_large
    run_large((48, 40), tmp_path)
    out = capsys.readouterr().out
    assert "peak" in out and "planes" in out and "process failed" not in out, out


def test_large_section_samples_each_stage_and_the_relighting_budget(tmp_path, capsys):
    # told of 64 GB free, the 48 x 40 slab fits whole: the whole reading's stages, each sampled
    from facette.bench._relight_large import run_large
    run_large((48, 40), tmp_path, free=64e9)
    out = capsys.readouterr().out
    assert "told of 64 GB free" in out and "CPU s" in out and "read: a budget of" in out, out
    assert "load+ps" in out and "relight model" in out and "(disk " in out, out
    assert (tmp_path / "large_samples.txt").read_text().count(" GB") > 0
