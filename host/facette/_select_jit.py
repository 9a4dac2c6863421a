"""Order statistics in compiled loops (numba), shared by the kernels that need a median without
a copy or a sort: the per-pixel LI solve (facette.fit._normals_li_jit) and the median over the
lights of `process`'s loading and report (facette.pipeline._pixels_jit); and the small sort of
rank_trimmed's windows (facette.recon._ps_robust_jit).

numba's cache keys a kernel on its own file: after editing this one, clear the callers'
__pycache__/*.nbc so that they recompile with it.
"""
from numba import njit

__all__ = ["insertion_sort", "kth_smallest", "median_in_place", "sort_prefix"]

SORT_BELOW = 24      # at most this many values: insertion sort (medians and `sort_prefix`)


@njit(cache=True)
def kth_smallest(v, n, kth):
    """The kth smallest of v[:n] (quickselect; v reordered so that v[:kth] hold smaller or equal ones)."""
    lo = 0
    hi = n - 1
    while lo < hi:
        pivot = v[(lo + hi) // 2]
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
        if kth <= j:
            hi = j
        elif kth >= i:
            lo = i
        else:
            return v[kth]
    return v[kth]


@njit(cache=True)
def insertion_sort(v, n):
    """v[:n] sorted in place (ascending): the fastest for a few dozen values, no call, no recursion."""
    for i in range(1, n):
        x = v[i]
        j = i - 1
        while j >= 0 and v[j] > x:
            v[j + 1] = v[j]
            j -= 1
        v[j + 1] = x


@njit(cache=True)
def sort_prefix(v, n):
    """v[:n] sorted in place: by insertion up to SORT_BELOW values, else numpy's sort."""
    if n <= SORT_BELOW:
        insertion_sort(v, n)
    else:
        v[:n].sort()


@njit(cache=True)
def median_in_place(v, n):
    """np.median of v[:n] (the same value: the middle one or the mean of the two), without
    np.median's copy; v reordered."""
    half = n >> 1
    if n <= SORT_BELOW:           # a few values: insertion sort (quickselect's partitions cost more)
        insertion_sort(v, n)
        return v[half] if n & 1 else (v[half - 1] + v[half]) / 2
    upper = kth_smallest(v, n, half)
    if n & 1:
        return upper
    lower = v[0]             # the largest of the half below
    for i in range(1, half):
        lower = max(lower, v[i])
    return (lower + upper) / 2
