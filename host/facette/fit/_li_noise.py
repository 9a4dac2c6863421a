"""The quantisation step of the values the LI model is fitted to, read from the values themselves.

Under few lights the (σ, n_i) fit and the model choice weigh each pixel's residuals relative to its
mean value (facette.fit._li_model). An 8-bit photograph's dark pixel (DiLiGenT's crops, a dark glossy
object: a mean of 4 levels of 255) carries a quantisation error of ±0.5 level, 7 % of its mean at one
sigma (1/√12 of a level): more than the fit's robust scale (5 %), so the dark pixels' noise outweighs
the highlights' misfit and the model choice finds no lobe (a dark paint σ 0.05 crater field, 12 rig
lights, 8-bit: 88 % of its values ≤ 5 levels, the last call fits σ 0.001, n_i 1: no BRDF step; there
the lobe clears the bar, and it is the fit that slides to n_i 1, pulled by the few pixels solved on
the lobe's peak: now fitted again on the pixels that cleared it, `_li_model.KEPT_MAX_LIGHTS`). The
noise is the sum of a constant part (quantisation, read noise) and one that grows with the value
(var = a + b I): `relative_floor` gives the constant part's floor, the smallest denominator at which
its noise is NOISE_SIGMAS below the robust scale.

The step is read as each (light, channel) column's smallest gap between two distinct values (the
values of one photograph, divided by its light's intensity, lie on a lattice; dark offsets shift it),
the median over the columns (a channel mixed of the others is finer): 8-bit photographs give their
level, 16-bit ones a level 257 × smaller, floats (no lattice) a gap near 0: no floor.

    quantum_step(e, usable) -> float
"""
import numpy as np

__all__ = ["quantum_step", "relative_floor", "NOISE_SIGMAS", "FLOOR_MAX_LIGHTS"]

# the fit's robust scale at least this many quantisation sigmas; 0: no floor. **Off by default**: on the
# 8 concave paint renders under the 12 rig lights cut to 8 bits (bench concave --bits 8) the scenes' mean
# errors summed: none 18.12, 2: 16.23, 4: 15.76, 8: 16.09 deg (dark craters 4.07 -> 2.61 / 2.60 / 2.67;
# the dark cup, whose inter-reflection removal swings it, 3.39 -> 2.92 / 2.97 / 3.40; 16-bit: 11.98 ->
# 11.97), so 4; confirmed against on DiLiGenT, 12 lights (bench diligent): 6.84 -> 6.92 deg (ball 1.68
# -> 1.70, buddha 8.55 -> 8.61, cat 5.11 -> 5.11, pot2 7.90 -> 8.25, reading 10.96 -> 10.92): pot2, whose
# brightest value is 68 of 255, has most of its pixels under the floor, and its fit then weighs its
# pixels by their values, not alike. Asked for with 4.0
NOISE_SIGMAS = 0.0
FLOOR_MAX_LIGHTS = 16  # above this many lights the fit averages the noise: no floor (96 and domes unchanged)


def quantum_step(e, usable):
    """The values' quantisation step (0 where none can be read): e (N, m, C), usable (N, m)."""
    e = np.asarray(e, np.float32)
    ok = np.asarray(usable, bool)[..., None] & np.isfinite(e)
    if e.shape[0] < 2:
        return 0.0
    col = np.sort(np.where(ok, e, np.nan).reshape(e.shape[0], -1), axis=0)
    gaps = np.diff(col, axis=0)
    gaps = np.where(gaps > 0, gaps, np.inf)
    low = gaps.min(0)
    low = low[np.isfinite(low)]
    return float(np.median(low)) if low.size else 0.0


def relative_floor(e, usable, f_scale=0.05, sigmas=None):
    """The smallest denominator of the fit's relative residuals (module doc): `sigmas` quantisation
    sigmas (step / √12; None: NOISE_SIGMAS) over the robust scale f_scale; 0 above FLOOR_MAX_LIGHTS
    lights or with sigmas 0 (the step is then not read)."""
    sigmas = NOISE_SIGMAS if sigmas is None else sigmas
    if np.shape(e)[1] > FLOOR_MAX_LIGHTS or sigmas <= 0:
        return 0.0
    return sigmas * quantum_step(e, usable) / np.sqrt(12.0) / f_scale
