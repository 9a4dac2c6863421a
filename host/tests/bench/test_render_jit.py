"""The large benches' render kernel: recon.synthetic.render's images, cheaper."""
import numpy as np
import pytest

from facette.bench._render_jit import render_lights
from facette.bench.lights import dome_lights
from facette.recon.synthetic import render, sphere_on_plane


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
