"""bench._convex_controls: the textured convex controls of `bench concave --controls`."""
import numpy as np

from facette.bench._convex_controls import local_controls
from facette.recon import scale_from_images
from facette.recon.synthetic import thesis_light_directions


def test_the_local_controls_are_textured_and_none_is_identified():
    scenes = local_controls(thesis_light_directions())
    assert {"slab/smooth", "slab/sharp", "slab/flat", "sphere/blotch", "satin sphere on plane"} <= set(scenes)
    for name, d in scenes.items():
        m, h, w, _ = d["images"].shape
        assert m == 12 and d["mask"].shape == (h, w) and np.isfinite(d["images"]).all(), name
        assert np.allclose(np.linalg.norm(d["normals"][d["mask"]], axis=-1), 1, atol=1e-5), name
    green = scenes["slab/sharp"]["images"][..., 1]
    assert np.ptp(green.max(axis=0)) > 0.05       # the pattern shows in the images
    for name in ("slab/smooth", "slab/sharp"):
        d = scenes[name]
        _, _, info = scale_from_images(d["images"], d["light_dirs"], d["mask"])
        assert not info["identified"], (name, info)
