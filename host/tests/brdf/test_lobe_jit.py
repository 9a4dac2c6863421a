"""The lobe's compiled pieces (facette.brdf._lobe_jit) against each other."""
import numpy as np

from facette.brdf._lobe_jit import SMITH_G1_TABLE, smith_g1_dlog_scaled, smith_g1_dlog_tabulated


def test_smith_g1_with_the_reciprocal_of_sigma_is_the_tabulated_one():
    # the per-pixel solve's form (1 / σ given, the table's spacing a constant) against the plain one:
    # the same table points, so the same values but for the last bits of the divisions it saves
    for sigma in (0.02, 0.1, 0.3, 0.8):
        for c in np.concatenate([np.linspace(-0.1, 1.1, 241), [0.0, 1.0, 1e-9, 1 - 1e-12]]):
            g, dlog = smith_g1_dlog_tabulated(c, sigma, SMITH_G1_TABLE)
            g2, dlog2 = smith_g1_dlog_scaled(c, 1.0 / sigma, SMITH_G1_TABLE)
            assert abs(g2 - g) <= 1e-12 * max(1.0, abs(g)), (sigma, c)
            assert abs(dlog2 - dlog) <= 1e-9 * max(1.0, abs(dlog)), (sigma, c)
    assert smith_g1_dlog_scaled(0.0, 10.0, SMITH_G1_TABLE) == (0.0, 0.0)
    assert smith_g1_dlog_scaled(1.0, 10.0, SMITH_G1_TABLE) == (1.0, 0.0)
