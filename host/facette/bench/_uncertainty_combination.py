"""A combination of the candidate measures chosen on renders only, confirmed on DiLiGenT (`facette bench
uncertainty --combination`; issue 50 item 3).

The bar is read per object (Spearman of the uncertainty against the error within each object), so the model
is fitted on ranks within each case: the error's rank (0-1) as a linear function of the measures' ranks
(0-1), each case weighted equally (least squares). Its score ranks each object's pixels; it is not a band
(no degrees, no coverage). Two figures come out of it:
- fitted on the render groups (synthetic spheres, Mitsuba scenes, concave scenes), scored on every case: a
  combination that would replace the band only if it beats it on the renders and then on DiLiGenT;
- a bound, fitted on the DiLiGenT objects themselves leaving the scored one out (never used for the map): what
  any linear rank combination of these measures can reach on an object it was not fitted on. Fitted on each
  object itself it shows how much of the order the measures hold in-sample.
"""
import numpy as np
from scipy.stats import rankdata, spearmanr

__all__ = ["COMBINED", "fit_rank_model", "rank_score", "leave_one_out"]

COMBINED = ("local fit", "curl", "normal variation 1px", "normal variation 3px", "view tilt", "front crb",
            "cast-shadow share", "edge distance", "highlight count")


def _ranks(v):
    """(N,) ranks in (0, 1] of v, non-finite values ranked last (least reliable)."""
    v = np.where(np.isfinite(v), v, np.inf)
    return rankdata(v) / len(v)


def _design(measures, names):
    cols = [_ranks(np.asarray(measures[k], np.float64)) for k in names]
    return np.column_stack(cols + [np.ones(len(cols[0]))])


def fit_rank_model(cases, names=COMBINED):
    """(len(names) + 1,) coefficients of the error's within-case rank on the measures' within-case ranks (and a
    constant); cases: [(measures {name: (N,)}, err (N,))], each weighted equally whatever its size."""
    if not cases:
        raise ValueError("fit_rank_model needs at least one case")
    a = np.vstack([_design(m, names) / np.sqrt(len(e)) for m, e in cases])
    b = np.concatenate([_ranks(e) / np.sqrt(len(e)) for _, e in cases])
    return np.linalg.lstsq(a, b, rcond=None)[0]


def rank_score(measures, coef, names=COMBINED):
    """(N,) the combination's score (high = unreliable) of one case's measures."""
    return _design(measures, names) @ coef


def leave_one_out(cases, names=COMBINED):
    """[Spearman of each case's score against its error, the model fitted on the other cases]."""
    out = []
    for i, (m, e) in enumerate(cases):
        coef = fit_rank_model([c for j, c in enumerate(cases) if j != i], names)
        out.append(float(spearmanr(rank_score(m, coef, names), e).statistic))
    return out
