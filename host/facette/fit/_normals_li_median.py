"""The median of the compiled per-pixel LI solve's robust scale (facette.fit._normals_li_jit: four
a pixel, of the |residuals| over its ~60 kept lights under a dome): np.median's value, as
facette._select_jit.median_in_place gives it, by a quickselect whose pivot is the median of three
and which ends in an insertion sort of the last SMALL_PART values (that part holds both middle values
of an even count, or the largest below them at its left). On a 6 MP 60-light dome band's pixels it took
the solve from 7.17 to 6.82 CPU µs a pixel (one thread), the same bits out (tests/fit/test_normals_li_median.py).

In its own file: numba caches a kernel by its file, and facette._select_jit serves other kernels.
"""
from numba import njit

__all__ = ["median_in_place", "SMALL_PART"]

SMALL_PART = 16          # parts of fewer values are insertion-sorted


@njit(cache=True)
def median_in_place(v, n):
    """np.median of v[:n] (v reordered), as facette._select_jit.median_in_place gives it: quickselect with a
    median-of-three pivot down to SMALL_PART values, then insertion sort of that part, which holds
    both middle values of an even count or the largest below them at its left."""
    half = n >> 1
    lo = 0
    hi = n - 1
    while hi - lo >= SMALL_PART:
        mid = (lo + hi) >> 1
        # median of three to v[mid]: fewer and more even partitions than the middle value alone
        if v[mid] < v[lo]:
            v[mid], v[lo] = v[lo], v[mid]
        if v[hi] < v[lo]:
            v[hi], v[lo] = v[lo], v[hi]
        if v[hi] < v[mid]:
            v[hi], v[mid] = v[mid], v[hi]
        pivot = v[mid]
        i = lo
        j = hi
        while i <= j:
            while v[i] < pivot:
                i += 1
            while v[j] > pivot:
                j -= 1
            if i <= j:
                v[i], v[j] = v[j], v[i]
                i += 1
                j -= 1
        if half <= j:
            hi = j
        elif half >= i:
            lo = i
        else:              # v[half] == pivot, between the two parts
            lo = hi = half
            break
    for a in range(lo + 1, hi + 1):       # insertion sort of v[lo:hi + 1]
        x = v[a]
        b = a - 1
        while b >= lo and v[b] > x:
            v[b + 1] = v[b]
            b -= 1
        v[b + 1] = x
    upper = v[half]
    if n & 1:
        return upper
    if half - 1 >= lo:
        return (v[half - 1] + upper) / 2
    lower = v[0]           # the largest of the values below the part
    for a in range(1, half):
        lower = max(lower, v[a])
    return (lower + upper) / 2
