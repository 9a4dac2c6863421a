"""The quality gate's word on the lights' geometry (facette.pipeline._quality.intensity_tilt)."""
import numpy as np

from facette.io.diligent import write_diligent
from facette.pipeline import process
from facette.pipeline._quality import RIG_TILT, TILT_NOTE_ABOVE, intensity_tilt
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def _ring(polar_deg, m=5, start=20.0):
    """m distant lights on a cone polar_deg from the view, evenly around it."""
    az = np.radians(start + 360.0 * np.arange(m) / m)
    t = np.radians(polar_deg)
    return np.stack([np.sin(t) * np.cos(az), np.sin(t) * np.sin(az), np.full(m, np.cos(t))], axis=1)


def test_the_tilt_figure_is_least_squares_own_sensitivity():
    # a flat Lambertian patch (normal +z) under each light set, every light's intensity 1 % off at
    # random: the least-squares normal's RMS tilt over many draws matches the figure
    rng = np.random.default_rng(0)
    for lights in (thesis_light_directions(), _ring(12.0), _ring(40.0, m=8)):
        e = lights[:, 2]
        tilts = []
        for _ in range(4000):
            g = np.linalg.lstsq(lights, e * (1 + 0.01 * rng.standard_normal(len(e))), rcond=None)[0]
            tilts.append(np.degrees(np.arctan2(np.hypot(g[0], g[1]), g[2])))
        rms = float(np.sqrt(np.mean(np.square(tilts))))
        assert abs(intensity_tilt(lights) - rms) < 0.05 * rms, (intensity_tilt(lights), rms)
    assert abs(intensity_tilt(thesis_light_directions()) - RIG_TILT) < 0.01
    assert intensity_tilt(_ring(12.0)) > 3 * intensity_tilt(_ring(40.0))       # lights near the view
    assert np.isnan(intensity_tilt(_ring(30.0)[:2])) and np.isnan(intensity_tilt(np.tile([[0, 0, 1.0]], (4, 1))))


def test_lights_near_the_view_get_a_note_with_the_figure(tmp_path):
    sc = sphere_on_plane(32, 32)
    for name, lights, noted in (("narrow", _ring(12.0), True), ("rig", thesis_light_directions(), False)):
        im = render(sc, lights, "matte")
        folder = tmp_path / name
        write_diligent(folder, np.round(im / im.max() * 60000).astype(np.uint16), lights)
        res = process(folder, outputs=["normals"], method="woodham1980")
        tilt = res.quality["normal_tilt_per_intensity_percent_deg"]
        assert tilt == round(intensity_tilt(lights), 3)
        said = [n for n in res.notes if "tilts the normals" in n]
        assert bool(said) == noted == (tilt > TILT_NOTE_ABOVE), (tilt, said)
        if noted:
            assert "12-12° from the view" in said[0] and f"{tilt:.1f}°" in said[0]
            banded = process(folder, outputs=["normals"], method="woodham1980", memory="1GB")   # --memory's path
            assert banded.quality["normal_tilt_per_intensity_percent_deg"] == tilt
            assert [n for n in banded.notes if "tilts the normals" in n] == said
