"""pipeline._channels: the colour channels the normal solve sees (green, mean, noise-weighted)."""
import json

import numpy as np
import pytest

from facette.io.diligent import write_diligent
from facette.methods import photometric_stereo
from facette.pipeline import ProcessOptions, process
from facette.pipeline._channels import SOLVE_CHANNEL, channel_weights, noise_variance, with_solve_channel
from facette.recon.synthetic import angular_error_deg, render, sphere_on_plane, thesis_light_directions

ALBEDO = (0.8, 0.25, 0.6)       # green the darkest channel: the one with the least signal


def _noisy_sphere(sigma=(0.01, 0.01, 0.01), seed=0, size=64):
    """A matte sphere of coloured albedo, additive noise of `sigma` per channel (read-noise-like)."""
    scene = sphere_on_plane(size, size)
    L = thesis_light_directions()
    im = render(scene, L, material="matte", albedo=ALBEDO)
    rng = np.random.default_rng(seed)
    im = im + rng.normal(size=im.shape).astype(np.float32) * np.asarray(sigma, np.float32)
    return scene, L, im.astype(np.float32)


def test_noise_variance_finds_each_channels_noise():
    scene, _, im = _noisy_sphere(sigma=(0.02, 0.01, 0.005), size=96)
    v = noise_variance(im, scene.mask)
    assert np.sqrt(v) == pytest.approx([0.02, 0.01, 0.005], rel=0.15)


def test_weights_are_global_snr_weights_summing_to_one():
    scene, _, im = _noisy_sphere(sigma=(0.01, 0.01, 0.01))
    w, note = channel_weights(im, scene.mask, "weighted")
    assert w.shape == (3,) and w.sum() == pytest.approx(1, abs=1e-6)
    # equal noise: weights follow each channel's mean signal, i.e. the albedo
    assert w / w.sum() == pytest.approx(np.asarray(ALBEDO) / sum(ALBEDO), abs=0.03)
    assert "estimated from the images" in note
    assert channel_weights(im, scene.mask, "green") == (None, "")
    assert channel_weights(im, scene.mask, "mean")[0] == pytest.approx([1 / 3] * 3)
    with pytest.raises(ValueError, match="channels must be one of"):
        channel_weights(im, scene.mask, "blue")


def test_weighted_beats_green_on_a_noisy_coloured_sphere():
    scene, L, im = _noisy_sphere()
    errs = {}
    for choice in ("green", "weighted"):
        w, _ = channel_weights(im, scene.mask, choice)
        x, ch = (im, 1) if w is None else (with_solve_channel(im, w), SOLVE_CHANNEL)
        r = photometric_stereo(x, L, method="woodham1980", mask=scene.mask, channel=ch)
        errs[choice] = float(np.mean(angular_error_deg(r.normal, scene.normals, scene.mask & r.valid)))
    assert errs["weighted"] < 0.8 * errs["green"], errs


def test_a_light_saturated_in_red_only_is_not_used():
    scene, L, _ = _noisy_sphere()
    im = render(scene, L, material="matte", albedo=ALBEDO)
    sat = 0.5
    im = np.minimum(im, 0.49)             # every value below saturation...
    k, (y, x) = 3, np.argwhere(scene.mask & (im[3, ..., 0] > 0.1))[0]
    im[k, y, x, 0] = 5.0                  # ...but red under light 3 at one pixel, which is wrong there
    w, _ = channel_weights(im, scene.mask, "mean")
    x4 = with_solve_channel(im, w, saturation=sat)
    assert np.isnan(x4[k, y, x, SOLVE_CHANNEL]) and np.isfinite(x4[k, y, x, :3]).all()
    assert np.isfinite(x4[:, scene.mask][..., SOLVE_CHANNEL].sum(0)).sum() > 0.9 * scene.mask.sum() - 1
    r = photometric_stereo(x4, L, method="woodham1980", mask=scene.mask, channel=SOLVE_CHANNEL, saturation=sat)
    assert angular_error_deg(r.normal[y:y + 1, x:x + 1], scene.normals[y:y + 1, x:x + 1]).max() < 1.0
    # the same light not taken out: the wrong red pulls the normal
    r_all = photometric_stereo(x4[..., :3], L, method="woodham1980", mask=scene.mask, channel=0)
    assert angular_error_deg(r_all.normal[y:y + 1, x:x + 1], scene.normals[y:y + 1, x:x + 1]).max() > 5.0


def test_missing_noise_falls_back_to_the_mean_with_a_note():
    scene = sphere_on_plane(32, 32)
    im = render(scene, thesis_light_directions(), material="matte", albedo=ALBEDO)
    w, note = channel_weights(im, scene.mask, "weighted", variance=np.array([np.nan, 1e-4, 1e-4]))
    assert w == pytest.approx([1 / 3] * 3) and "not usable" in note and "the mean of R, G, B instead" in note
    w, note = channel_weights(im, np.zeros((32, 32), bool), "weighted")      # nothing to estimate it on
    assert w == pytest.approx([1 / 3] * 3) and "estimated from the images" in note
    with pytest.raises(ValueError, match="one value per channel"):
        channel_weights(im, scene.mask, "weighted", variance=np.ones(2))


def test_process_records_the_channels_and_keeps_albedo_per_colour(tmp_path):
    scene, L, im = _noisy_sphere()
    k = 60000.0 / float(im.max())
    folder = tmp_path / "sphere"
    write_diligent(folder, np.clip(np.round(np.maximum(im, 0) * k), 0, 65535).astype(np.uint16), L,
                   np.full((len(im), 3), k / 65535.0), scene.mask)
    res = {}
    for choice in ("green", "weighted"):
        out = tmp_path / choice
        res[choice] = process(folder, outputs=["normals", "albedo"], out_dir=out,
                              options=ProcessOptions(method="woodham1980", channels=choice))
        rec = json.loads((out / "process.json").read_text())
        assert rec["options"]["channels"] == choice and rec["ps_channels"]["channels"] == choice
    assert res["weighted"].albedo.shape == scene.normals.shape        # R, G, B, the solve channel dropped
    assert res["weighted"].ps.info["channels"]["weights"][0] > res["weighted"].ps.info["channels"]["weights"][1]
    assert any(n.startswith("channels: normals on") for n in res["weighted"].notes)
    err = {c: float(np.mean(angular_error_deg(r.normals, scene.normals, scene.mask & r.mask))) for c, r in res.items()}
    assert err["weighted"] < err["green"], err
    with pytest.raises(Exception, match="channels must be one of"):
        ProcessOptions(channels="blue")
