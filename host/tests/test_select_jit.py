"""facette._select_jit: the order statistics of the compiled loops are numpy's."""
import numpy as np

from facette._select_jit import SMALL_PART, kth_smallest, median_in_place


def test_median_is_numpys_for_every_count_with_and_without_ties():
    rng = np.random.default_rng(3)
    for n in range(1, 3 * SMALL_PART + 40):
        for values in (rng.random(n), rng.integers(0, 4, n).astype(np.float64), np.full(n, 2.5),
                       np.arange(n, dtype=np.float64)[::-1]):
            v = np.concatenate([values, [np.inf, -1.0]])      # values past n are never read
            assert median_in_place(v, n) == np.median(values)


def test_median_reorders_only_the_first_n_values():
    v = np.array([5.0, 1.0, 4.0, 2.0, 3.0, 9.0, -7.0])
    assert median_in_place(v, 5) == 3.0
    assert sorted(v[:5]) == [1.0, 2.0, 3.0, 4.0, 5.0] and list(v[5:]) == [9.0, -7.0]


def test_kth_smallest_is_the_sorted_value_and_partitions_below_it():
    rng = np.random.default_rng(4)
    for n in range(1, 3 * SMALL_PART + 40):
        for values in (rng.random(n).astype(np.float32), rng.integers(0, 4, n).astype(np.float32)):
            for kth in {0, n // 3, n // 2, n - 1}:
                v = values.copy()
                assert kth_smallest(v, n, kth) == np.sort(values)[kth]
                assert (v[:kth] <= v[kth]).all() and sorted(v) == sorted(values)
