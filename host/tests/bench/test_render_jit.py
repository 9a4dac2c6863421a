"""The large benches' render kernel: recon.synthetic.render's images, cheaper."""
import numpy as np
import pytest

from facette.bench._render_jit import cast_hidden, render_lights
from facette.bench.lights import dome_lights
from facette.recon.synthetic import render, sphere_on_plane

from shadow_scenes import groove_scene


@pytest.mark.parametrize("material", ["satin", "glossy", "matte"])
def test_the_kernel_renders_what_render_renders(material):
    scene = sphere_on_plane(24, 30)            # every orientation up to grazing, and the flat plane
    lights = dome_lights(7)
    want = render(scene, lights, material, cast_shadows=False)
    got = render_lights(scene.normals, lights, material, np.empty_like(want))
    assert np.count_nonzero(want) > want.size // 2
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9)


def test_an_unknown_material_is_refused():
    with pytest.raises(ValueError, match="unknown material"):
        render_lights(np.zeros((2, 2, 3)), dome_lights(3), "velvet", np.empty((3, 2, 2, 3), np.float32))


def test_the_cast_shadows_are_the_rays_that_meet_the_surface():
    d = groove_scene("groove")             # its truth: each ray marched on the analytic heights
    rows, cols = np.mgrid[0:96, 0:96]
    heights = -18.0 * np.maximum(0.0, 1 - ((cols - 48.0) / 16.0) ** 2)       # shadow_scenes' groove
    got = cast_hidden(heights, 0, 96, d["light_dirs"])
    assert d["hidden"].sum() > 10_000
    # none found that is not hidden; a few missed where the steps past 10 px step over the groove's
    # sharp rim (the bench's relief is smooth: 0.017 % of its lit samples decided otherwise than by 0.25 px steps)
    assert (got & ~d["hidden"]).sum() <= 1e-3 * d["hidden"].sum()
    assert (got & d["hidden"]).sum() >= 0.97 * d["hidden"].sum()
    # a band's rows are the whole image's, marched over the rows outside it
    np.testing.assert_array_equal(cast_hidden(heights, 30, 50, d["light_dirs"]), got[:, 30:50])


def test_a_plane_and_a_light_on_the_axis_cast_no_shadow():
    lights = np.array([[0.0, 0.0, 1.0], [0.98, 0.0, 0.199]])
    assert not cast_hidden(np.zeros((8, 9)), 0, 8, lights).any()
    wall = np.zeros((8, 9))
    wall[:, 6:] = 50.0
    got = cast_hidden(wall, 0, 8, lights)
    assert not got[0].any() and got[1][:, :6].all() and not got[1][:, 6:].any()
