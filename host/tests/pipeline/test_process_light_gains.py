"""`process` reads the lights' gains from a folder's photographs (pipeline._light_gains)."""
import json

import numpy as np
import pytest

from facette.errors import BadInputError
from facette.io.diligent import write_diligent
from facette.pipeline import process
from facette.recon.synthetic import angular_error_deg, render, sphere_on_plane, thesis_light_directions


def _folder(path, lights, gains):
    """A DiLiGenT-style folder of a satin sphere whose lights were `gains` times as bright as its
    light_intensities.txt (ones) says."""
    sc = sphere_on_plane(40, 40)
    im = render(sc, lights, "satin") * np.asarray(gains)[:, None, None, None]
    write_diligent(path, np.round(im / im.max() * 60000).astype(np.uint16), lights, np.ones((len(lights), 3)))
    return sc


def test_a_folders_intensities_off_by_3_percent_are_corrected_from_its_photographs(tmp_path):
    lights = thesis_light_directions()
    gains = 1 + 0.03 * np.sin(np.arange(len(lights)) * 1.7)
    sc = _folder(tmp_path / "f", lights, gains)
    res = process(tmp_path / "f", outputs=["normals"], out_dir=tmp_path / "out")
    kept = process(tmp_path / "f", outputs=["normals"], light_gains=False)
    lg = res.light_gains
    assert lg["applied"] and kept.light_gains is None
    read = np.asarray(lg["gains"])
    truth = gains / np.exp(np.mean(np.log(gains)))
    assert np.max(np.abs(read / truth - 1)) < 0.01
    obj = sc.sphere & res.mask
    err, err_kept = (float(np.mean(angular_error_deg(r.normals, sc.normals, obj))) for r in (res, kept))
    assert err < 0.6 * err_kept, (err, err_kept)
    assert any(n.startswith("light gains: the photographs put the given intensities") for n in res.notes)
    rec = json.loads((tmp_path / "out" / "process.json").read_text())
    assert rec["light_gains"]["gains"] == lg["gains"] and rec["options"]["light_gains"] == "auto"


def test_lights_bunched_near_the_axis_keep_their_intensities_and_say_why(tmp_path):
    az = np.radians(20 + 72.0 * np.arange(5))
    t = np.radians(12.0)
    lights = np.stack([np.sin(t) * np.cos(az), np.sin(t) * np.sin(az), np.full(5, np.cos(t))], axis=1)
    _folder(tmp_path / "f", lights, np.ones(5))
    res = process(tmp_path / "f", outputs=["normals"])
    assert res.light_gains is None
    assert any(n.startswith("light gains: the given intensities are kept (under these lights") for n in res.notes)
    with pytest.raises(BadInputError, match="light_gains must be True, False or 'auto'"):
        process(tmp_path / "f", outputs=["normals"], light_gains="yes")
