"""Per-pixel loops of `process`'s channel choice, compiled (numba): one pass over the pixels where
numpy makes one pass per operation and a temporary for each (the loaders' own loops are in
capture._pixels_jit).

Imported on first use (numba takes ~0.4 s to import); the kernels release the GIL, so that
callers can run them on row blocks on their own threads.
"""
import numpy as np
from numba import njit

__all__ = ["append_weighted"]


@njit(cache=True, nogil=True)
def _append_weighted(images, w, sat, out, l0, l1):
    c = images.shape[3]
    for li in range(l0, l1):
        for i in range(images.shape[1]):
            for j in range(images.shape[2]):
                acc = np.float32(0)
                bad = False
                for k in range(c):
                    x = images[li, i, j, k]
                    out[li, i, j, k] = x
                    if w[k] != 0:
                        acc += w[k] * x
                        bad = bad or not (x - x == 0) or x >= sat     # NaN or inf, or saturated
                out[li, i, j, c] = np.nan if bad else acc


def append_weighted(images, weights, saturation, out, lights):
    """out[lights] = images[lights] with sum_k weights_k images_k appended as the last channel, NaN
    there where a weighted channel is not finite or >= saturation (None: no limit).
    images : (m, H, W, C) float32; weights : (C,) float32; out : (m, H, W, C + 1) float32;
    lights : a slice."""
    l0, l1, _ = lights.indices(images.shape[0])
    sat = np.float32(np.inf) if saturation is None else np.float32(saturation)
    _append_weighted(images, np.asarray(weights, np.float32), sat, out, l0, l1)
