"""The (σ, n_i) node grid of the tables that fits read at any (σ, n_i): the LI volume part's
(facette.brdf._volume.volume_table_at) and the coupled part's transmittance
(facette.brdf._coupled.coupled_transmittance). A table is computed once per node and the nodes
around (σ, n_i) are combined linearly in log σ and in n_i, so the result is continuous in both and
a finite-difference Jacobian sees the model, not the grid.

    nodes_around(sigma, n_i) -> [(i, j, weight)]   the nodes with a weight > 0, weights summing to 1
    node_point(i, j) -> (sigma, n_i)
"""
import numpy as np

__all__ = ["NODE_SIGMA_MIN", "NODE_SIGMA_RATIO", "NODE_N_I_STEP", "node_point", "nodes_around"]

NODE_SIGMA_MIN = 1e-3           # σ nodes NODE_SIGMA_MIN · NODE_SIGMA_RATIO^i (below: the first node)
NODE_SIGMA_RATIO = 1.2
NODE_N_I_STEP = 0.025           # n_i nodes 1 + j · NODE_N_I_STEP


def _cell(x, step):
    """(k, w): the grid cell [k, k + 1] of x in units of `step` (x ≥ 0) and the weight of k + 1."""
    u = max(float(x) / step, 0.0)
    k = int(np.floor(u))
    return k, u - k


def node_point(i, j):
    """(σ, n_i) of node (i, j)."""
    return NODE_SIGMA_MIN * NODE_SIGMA_RATIO ** i, 1.0 + j * NODE_N_I_STEP


def nodes_around(sigma, n_i):
    """[(i, j, weight)] of the (up to four) nodes around (σ, n_i) with a weight > 0, bilinear in
    log σ and n_i, in the order (i, j), (i, j + 1), (i + 1, j), (i + 1, j + 1)."""
    ks, ws = _cell(np.log(max(float(sigma), NODE_SIGMA_MIN) / NODE_SIGMA_MIN), np.log(NODE_SIGMA_RATIO))
    kn, wn = _cell(float(n_i) - 1.0, NODE_N_I_STEP)
    return [(i, j, wi * wj) for i, wi in ((ks, 1 - ws), (ks + 1, ws)) for j, wj in ((kn, 1 - wn), (kn + 1, wn))
            if wi * wj != 0]
