"""Order statistics in compiled loops (numba), shared by the kernels that need a median without
a copy or a sort: the per-pixel LI solve (facette.fit._normals_li_jit) and the median over the
lights of `process`'s loading and report (facette.pipeline._pixels_jit); and the bounds of
rank_trimmed's windows (facette.recon._ps_robust_jit: two `kth_smallest`, or a small sort).

numba inlines these into their callers' cached machine code: facette._kernel_cache gives every
version of the kernels' sources a cache folder of its own, so a caller never keeps an old copy.
"""
from numba import njit

__all__ = ["insertion_sort", "kth_smallest", "median_in_place", "sort_prefix", "SMALL_PART"]

SORT_BELOW = 24      # at most this many values: insertion sort (medians and `sort_prefix`)
SMALL_PART = 16      # `kth_smallest`: a part of fewer values is insertion-sorted


@njit(cache=True)
def kth_smallest(v, n, kth):
    """The kth smallest of v[:n] (quickselect; v reordered so that v[:kth] hold smaller or equal ones).
    The pivot is the median of three, and a part of fewer than SMALL_PART values is insertion-sorted:
    the middle value alone as pivot cost more partitions (the per-pixel LI solve's robust scale,
    four medians a pixel of ~60 values under a dome: 7.17 -> 6.82 CPU µs a pixel; rank_trimmed's
    window bounds likewise; the same values)."""
    lo = 0
    hi = n - 1
    while hi - lo >= SMALL_PART:
        mid = (lo + hi) >> 1
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
        if kth <= j:
            hi = j
        elif kth >= i:
            lo = i
        else:                # v[kth] equals the pivot, between the two parts
            return v[kth]
    for a in range(lo + 1, hi + 1):       # insertion sort of the part left, v[lo:hi + 1]
        x = v[a]
        b = a - 1
        while b >= lo and v[b] > x:
            v[b + 1] = v[b]
            b -= 1
        v[b + 1] = x
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
