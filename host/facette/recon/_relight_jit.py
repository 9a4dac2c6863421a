"""The relighting model's per-pixel normal equations (`recon._relight_model._normal_equations`),
compiled (numba): one pass over a block where numpy made nine products and reductions, each with a
temporary (the report's model at 4288x2848, 12 lights: 0.5 of its 3.3 CPU s). The same float32
products summed over the lights in float64, light after light: the values of numpy's reduction,
bit for bit. Imported on first use; releases the GIL."""
import numpy as np
from numba import njit

__all__ = ["normal_equations"]


@njit(cache=True, nogil=True)
def normal_equations(basis, values, weights, gram, rhs):
    """gram (N, 3, 3) and rhs (N, 3, C) float64 filled: 0.0 + Σ_i float32(float32(b_ij w_i) b_ik) and
    0.0 + Σ_i float32(float32(b_ij w_i) y_ic) over the lights i in order, of basis (m, N, 3), values
    (m, N, C) and weights (m, N), all float32."""
    m, n, nc = basis.shape[0], basis.shape[1], values.shape[2]
    for p in range(n):
        for j in range(3):
            for k in range(j, 3):
                acc = 0.0              # numpy's reduction starts from +0.0 too (a sum of -0.0s is +0.0)
                for i in range(m):
                    acc += np.float64(np.float32(basis[i, p, j] * weights[i, p]) * basis[i, p, k])
                gram[p, j, k] = acc
                gram[p, k, j] = acc
            for c in range(nc):
                acc = 0.0
                for i in range(m):
                    acc += np.float64(np.float32(basis[i, p, j] * weights[i, p]) * values[i, p, c])
                rhs[p, j, c] = acc
