"""Cast-shadow flags no neighbour shares (facette.fit._ps_li_flags) and the solve that takes them back
(`Pixels.solve_isolated_flags`)."""
import numpy as np

from facette.fit._ps_li_flags import isolated_flags


def _grid(h=8, w=8, m=3):
    idx = np.arange(h * w)
    return np.zeros((idx.size, m), bool), np.ones((idx.size, m), bool), idx, (h, w)


def test_a_flag_no_neighbour_shares_is_isolated_and_a_shadows_region_is_not():
    shadow, usable, idx, shape = _grid()
    shadow[[r * 8 + c for r in range(4, 8) for c in range(4, 8)], 0] = True    # a shadow's corner region
    shadow[2 * 8 + 2, 1] = True                                               # one pixel alone
    out = isolated_flags(shadow, usable, idx, shape)
    assert out.dtype == bool and out.shape == (64,)
    assert np.flatnonzero(out).tolist() == [2 * 8 + 2]


def test_a_neighbour_that_cannot_use_the_light_or_the_images_edge_leaves_the_flag_alone():
    shadow, usable, idx, shape = _grid()
    shadow[2 * 8 + 2, 1] = True
    usable[2 * 8 + 3, 1] = False            # a neighbour saturated or NaN on that light: it does not keep it
    shadow[0 * 8 + 5, 2] = True             # on the image's edge: 5 neighbours, all keep it
    shadow[0 * 8 + 0, 2] = True             # in its corner: 3 neighbours, too few to say
    out = isolated_flags(shadow, usable, idx, shape)
    assert np.flatnonzero(out).tolist() == [5]
    # the valid pixels only count as neighbours: the others left out of idx
    keep = np.setdiff1d(idx, [1 * 8 + 4, 1 * 8 + 5, 1 * 8 + 6])
    out = isolated_flags(shadow[keep], usable[keep], keep, shape)
    assert not out.any()


def test_no_flag_nothing_isolated():
    shadow, usable, idx, shape = _grid()
    assert not isolated_flags(shadow, usable, idx, shape).any()
