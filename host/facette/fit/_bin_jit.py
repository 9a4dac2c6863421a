"""Compiled block means of the images for the coarse pass of `ps_li_alternating`
(`facette.fit._ps_li_coarse`: the (σ, n_i) fit and the model choice on f × f binned pixels);
numba, cache=True, loaded only when li_alternating runs."""
import math

import numpy as np
from numba import njit, prange

__all__ = ["bin_images"]


@njit(cache=True, parallel=True)
def _bin_kernel(images, mask, f, saturation, out):
    m, h, w, c = images.shape
    hc, wc = out.shape[1], out.shape[2]
    for i in prange(m):
        for by in range(hc):
            for bx in range(wc):
                for ch in range(c):
                    tot = 0.0
                    cnt = 0
                    for y in range(by * f, min((by + 1) * f, h)):
                        for x in range(bx * f, min((bx + 1) * f, w)):
                            v = images[i, y, x, ch]
                            if mask[y, x] and math.isfinite(v) and v < saturation:
                                tot += v
                                cnt += 1
                    out[i, by, bx, ch] = tot / cnt if 2 * cnt >= f * f else np.nan


def bin_images(images, mask, f, saturation=None):
    """(m, ceil(H/f), ceil(W/f), C) float32 block means of the masked, finite values below
    `saturation` of (m, H, W, C) images; NaN where fewer than half the block's f × f pixels count."""
    m, h, w, c = images.shape
    out = np.empty((m, -(-h // f), -(-w // f), c), np.float32)
    _bin_kernel(images, np.ascontiguousarray(mask, bool), int(f),
                np.inf if saturation is None else float(saturation), out)
    return out
