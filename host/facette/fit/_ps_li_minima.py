"""A search of each pixel's minima in the BRDF-aware per-pixel solve (`Pixels.search_minima`).

Under the rig's 12 lights a pixel's robust cost against the fitted LI model has several minima, and
the local solve (facette.fit._normals_li) ends in the one its start leads to. The search solves the
pixel again from starts spread over the hemisphere (MINIMA_STARTS fixed directions and, per light,
the normal that puts it at the lobe's centre: its half-vector), screened by their cost at the start,
the KEEP cheapest solved; the pixel keeps the minimum of lowest robust cost (its own values decide,
the cost on the scale of its first solve so that the starts compare). The cost of the best other
minimum is kept too: the relative gap between the two is how sure the pixel is of its choice.

    search_pixel_minima(values, usable, normals, lights, sigma, n_i, volume_model) -> Minima

Only pixels that need it are searched: those whose normal stands more than SEARCH_ABOVE_DEG from
their 5 × 5 neighbours' mean (`Pixels.search_minima`); distant lights only (the compiled solve).

A pixel moves to the cheaper minimum only toward its neighbours (`Pixels._move_to_cheaper`): nearer their mean
than its normal. Why: on DiLiGenT cat under 12 lights (looked at, not chosen on), searching from 4° took
the mean from 5.16 to 5.24°: 6141 pixels searched, 1041 moved, 368 of them nearer the truth by > 1° and
603 further. The moves that lost started near their neighbours (median 7° from their mean) and went
further (11°); their darkest values were lit, 8-bit (5 of 255), and the minimum reached from their TRUE
normal cost more than the one found (9.4 against 7.6): the data decide there, the search cannot. The
moves that gained came from 21° to 9° off, their darkest values cast shadows (1 of 255). Summed over the
moved pixels' errors: toward the neighbours −5980°, away +5048° (at 7°: −6091°, +1892°).
Chosen on the 8 concave paint renders, 12 rig lights, through `process` (the scenes' mean errors summed,
16-bit: 12.98 -> 12.01°, craters paint 2.59 -> 2.10, dark cup 1.65 -> 1.20; bench concave --bits 8, the
dark cup left aside: 15.49 -> 14.73. That cup swings 2.79 / 4.58 / 3.39° (before / this / with the
isolated flags too): its inter-reflections are removed at a scale of 5.9, from normals a few pixels apart;
left in, 3.04 -> 3.03). With it, searching from 4° instead of 7 summed 11.96 (16-bit) and 15.20 (8-bit
with the isolated flags, the cup aside; 7: 14.73).
"""
from dataclasses import dataclass

import numpy as np

from ._normals_li import CAST_SHADOW_RATIO, MAX_STEP, SCALE_FLOOR
from ._orientation import hemisphere

__all__ = ["search_pixel_minima", "Minima", "minima_starts", "relative_gap", "SEARCH_ABOVE_DEG", "SEARCH_MAX_LIGHTS"]

MINIMA_STARTS = 24     # fixed start directions over the hemisphere (Fibonacci set, z > 0.1)
KEEP = 3               # starts solved per pixel: those of lowest cost at the start
MIN_SEP_DEG = 5.0      # two minima closer than this are one
ITERATIONS = 12        # steps of each solve
STEP_TOL = 1e-3        # rad: a start's solve stops below this step (the rounds' ROUND_STEP_TOL)
# a pixel is searched when its normal is this far from its 5 x 5 neighbours' mean. Chosen on renders
# under the 12 rig lights (li_sphere of our own, LI model, dark glossy, 8-bit; 8 concave scenes in
# paint_0.10 and dark paint_0.05): on the BRDF-aware pixels' error right after the search, summed over
# the nine, searching every one gained 1.66 deg of mean error, those > 5 deg off 1.66 (7-27 % of the
# pixels), > 7 deg 1.67 (1-20 %): the other pixels' moves lose on balance. The scenes' final errors
# through `process` (none, > 7, > 4 deg, all): summed 15.57, 15.28, 15.20, 15.35 deg; 4 was measured
# too late to be confirmed on the benches
SEARCH_ABOVE_DEG = 7.0
# under many lights the values decide the minimum (the issue is the rig's 12): no search above this
# many lights, so that DiLiGenT's 96 and a dome's give the same normals as without it
SEARCH_MAX_LIGHTS = 16


@dataclass
class Minima:
    """normals (N, 3): the best minimum found (the first solve's where no other is cheaper);
    cost_here (N,): the robust cost of the solve from the current normal; cost_best, cost_second (N,):
    the lowest cost and that of the best other minimum (> MIN_SEP_DEG away; inf: none found)."""
    normals: np.ndarray
    cost_here: np.ndarray
    cost_best: np.ndarray
    cost_second: np.ndarray


def relative_gap(cost_best, cost_second):
    """(N,) the second minimum's cost above the best's, relative: (c2 − c1) / (c2 + c1) in [0, 1]
    (1: no other minimum found, or the best explains the pixel exactly)."""
    c1, c2 = np.asarray(cost_best, np.float64), np.asarray(cost_second, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        g = (c2 - c1) / (c2 + c1)
    return np.where(np.isfinite(c2) & (c2 + c1 > 0), g, 1.0)


def minima_starts(lights, count=MINIMA_STARTS):
    """(count + m, 3) float32 unit starts: `count` directions spread over z > 0.1 and each light's
    half-vector with the view (0, 0, 1)."""
    h = hemisphere(int(count / 0.9) + 1)
    h = h[h[:, 2] > 0.1][:count]
    half = np.asarray(lights, np.float32) + np.float32([0, 0, 1])
    half = half / np.linalg.norm(half, axis=1, keepdims=True)
    return np.concatenate([h, half]).astype(np.float32)


def search_pixel_minima(values, usable, normals, lights, sigma, n_i, volume_model, keep=KEEP,
                        starts=None, table=None):
    """The minima search (module doc) of N pixels.

    values : (N, m, C) over the lights' intensities; usable : (N, m) bool; normals : (N, 3) the
    current normals; lights : (m, 3) distant; sigma, n_i, volume_model : the fitted model.
    Returns a `Minima`."""
    from ._ps_li_minima_jit import search_minima_compiled    # numba loads only when it runs
    starts = minima_starts(lights) if starts is None else starts
    best, here, c1, c2 = search_minima_compiled(values, usable, normals, starts, lights, sigma, n_i, ITERATIONS,
                                                keep, MIN_SEP_DEG, CAST_SHADOW_RATIO, SCALE_FLOOR, MAX_STEP,
                                                STEP_TOL, volume_model=volume_model, table=table)
    return Minima(normals=best, cost_here=here, cost_best=c1, cost_second=c2)

