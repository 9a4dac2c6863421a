"""The rank combination of the uncertainty's candidate measures (bench._uncertainty_combination): it finds the
measure that orders the errors among ones that do not, weighs each case alike, and its leave-one-out score
of a case comes from the other cases only (where they hold the opposite order, it ranks the case backwards)."""
import numpy as np
import pytest
from scipy.stats import spearmanr

from facette.bench._uncertainty_combination import fit_rank_model, leave_one_out, rank_score

NAMES = ("good", "noise")


def _case(n, seed, good=True, sign=1.0):
    rng = np.random.default_rng(seed)
    err = rng.gamma(2.0, 1.0, n)
    signal = sign * err if good else rng.permutation(err)
    return {"good": signal + 0.3 * rng.normal(size=n), "noise": rng.normal(size=n)}, err


def test_the_measure_that_orders_the_errors_gets_the_weight():
    cases = [_case(400, s) for s in range(4)]
    coef = fit_rank_model(cases, NAMES)
    assert coef[0] > 0.7 and abs(coef[1]) < 0.1
    m, e = _case(500, 9)
    assert spearmanr(rank_score(m, coef, NAMES), e).statistic > 0.8


def test_each_case_counts_alike_whatever_its_size():
    big, small = _case(5000, 1, good=False), _case(50, 2)
    alike = fit_rank_model([big, small, small], NAMES)
    assert alike[0] > 0.25            # a size-weighted fit would give the 5000-pixel case 98 % of the say


def test_leave_one_out_scores_each_case_on_a_model_it_was_not_fitted_on():
    cases = [_case(300, 1), _case(300, 2, sign=-1.0), _case(300, 3, sign=-1.0)]
    loo = leave_one_out(cases, NAMES)
    assert len(loo) == 3 and loo[0] < -0.8         # fitted on its own data it would rank it at ~0.95
    with pytest.raises(ValueError):
        fit_rank_model([], NAMES)
