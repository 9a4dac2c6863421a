"""The Python reference of the viewer: the LI model per pixel, and what it refuses."""
import numpy as np
import pytest

import facette.brdf as brdf
from facette.pipeline._relight import (ViewerModel, kd_map_from_albedo, light_from_angles, relight,
                                       viewer_model)
from facette.reflect import local_frame_directions


def test_relight_is_the_li_model_times_the_cosine():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(6, 5, 3))
    n[..., 2] = np.abs(n[..., 2]) + 0.3
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    kd = np.array([0.7, 0.4, 0.2])
    m = ViewerModel("li", kd, 0.2, 1.45, volume="approx")
    light = light_from_angles(30.0, 50.0)
    got = relight(n, np.broadcast_to(kd, n.shape), np.ones(n.shape[:2], bool), m, light)
    s, o = local_frame_directions(n.reshape(-1, 3), light, [0.0, 0.0, 1.0])
    f = brdf.brdf_li(s.astype(float), o.astype(float), kd, 0.2, 1.45, volume="approx")
    want = np.where(s[:, 2:3] > 0, f * s[:, 2:3], 0).reshape(got.shape)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-9)


def test_viewer_refuses_what_it_cannot_draw():
    with pytest.raises(ValueError, match="fit failed"):
        viewer_model({"model": "li", "success": False, "message": "no data", "parameters": {}})
    with pytest.raises(ValueError, match="draws the"):
        viewer_model({"model": "oren_nayar", "success": True, "parameters": {"kd": [0.5], "sigma": 0.2}})
    with pytest.raises(ValueError, match="isotropic"):
        viewer_model({"model": "li", "success": True, "parameters": {"kd": [0.5], "sigma": [0.1, 0.2], "n_i": 1.5}})
    kd = kd_map_from_albedo(np.full((4, 4, 3), 2.0), np.ones((4, 4), bool), [0.6, 0.5, 0.4])
    np.testing.assert_allclose(kd[0, 0], [0.6, 0.5, 0.4])
