"""bench/peers.py: the renders ST14's constants are chosen on, and the papers' figures."""
import numpy as np

from facette.bench.peers import paper_figure, st14_render


def test_st14_render_is_cut_to_its_grey_levels_and_keeps_its_floor():
    img, lights, mask, n = st14_render("satin", 40, 0.02, size=16, m=12)
    assert img.shape == (12, 16, 16) and lights.shape == (12, 3) and n.shape == (16, 16, 3)
    assert np.allclose(np.linalg.norm(lights, axis=1), 1) and np.all(lights[:, 2] > 0.49)
    levels = img[:, mask] * 40 / (0.5 / np.pi)
    assert np.allclose(levels, np.round(levels), atol=1e-3)      # whole grey levels
    # stray light (16 bits: at 40 levels a 2 % floor is under one level): no pixel of the sphere
    # is black, even where a light is behind it
    lit, _, _, _ = st14_render("satin", 10000, 0.02, size=16, m=12)
    assert np.all(np.nanmin(lit[:, mask], axis=0) > 0)
    dark, _, _, _ = st14_render("satin", 10000, 0.0, size=16, m=12)
    assert np.any(dark[:, mask] == 0)


def test_paper_figures_of_the_peers():
    assert paper_figure("st14", "ball") == 1.74
    assert paper_figure("bivariate_ikehata2014", "reading") == 14.19
    assert paper_figure("woodham1980", "ball") is None
