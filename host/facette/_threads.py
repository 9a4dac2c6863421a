"""The one way facette runs independent blocks of work on threads: numpy, OpenCV's PNG decoder
and the `nogil` numba kernels give the GIL up, so two threads use both cores of the rig's host."""
from concurrent.futures import ThreadPoolExecutor

__all__ = ["WORKERS", "run_blocks"]

WORKERS = 2   # threads for independent blocks (the machines facette is sized for have 2 cores)


def run_blocks(fn, starts, workers=WORKERS):
    """[fn(a) for a in starts], on `workers` threads when there is more than one block (in order;
    a block's error is raised here). The blocks must write disjoint slices."""
    starts = list(starts)
    if workers > 1 and len(starts) > 1:
        with ThreadPoolExecutor(workers) as pool:
            return list(pool.map(fn, starts))
    return [fn(a) for a in starts]
