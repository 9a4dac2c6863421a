"""Two bands of `process --memory` solved at once on this machine (`_tiled_process.band_loop`).

A band's solve under a 60-light dome is half compiled loops that use both cores (rank_trimmed,
the per-pixel LI solve) and half steps that use one (gathering the pixels' values, the shadows
settled, the results scattered back: numpy, one thread). One band after the other, the second
core waits through those: a 6 MP 60-light band of 438 000 pixels took 9.5 CPU s, of which ~3.5 on
one thread. Two bands in flight keep both cores busy; their rows are those the budget gives one
band of twice the photographs, so that the two hold what one band did. Each pixel's solve depends only on its own values
and the model shared by the bands, so the results are the same bytes (the bands' results are
taken in order); numba's threading layer here (omp) takes parallel calls from two threads.
"""
import os
from collections import deque
from concurrent.futures import ThreadPoolExecutor

__all__ = ["BANDS_IN_FLIGHT", "InFlight", "rows_in_flight", "in_order_on_threads"]

BANDS_IN_FLIGHT = 2      # bands solved at once (on a machine of at least as many cores)


def rows_in_flight(rows_for, m, height, given):
    """(rows of a band, bands at once) for m photographs: rows_for(lights) -> the rows one band of that many
    photographs gets in the budget (`_tiled_process.band_rows`), asked for k = BANDS_IN_FLIGHT x m, so
    that k bands at once hold what one band of the budget's rows would; one band at a time when the
    rows were given, on a single core, when k bands of even the fewest rows do not fit, or when the
    image is one band."""
    k = min(BANDS_IN_FLIGHT, os.cpu_count() or 1)
    if not given and k > 1:
        try:
            n = rows_for(k * m)
            if n < height:
                return n, k
        except ValueError:       # k bands of the fewest rows do not fit: one at a time
            pass
    return rows_for(m), 1


class InFlight:
    """`open_capture`'s rows_for(w, h, m, maps_bytes) from band_rows(w, h, lights, maps_bytes), which
    remembers the bands at once it chose (`threads`, `rows_in_flight`); given: the rows were given."""

    def __init__(self, band_rows, given):
        self.band_rows, self.given, self.threads = band_rows, given, 1

    def rows_for(self, w, h, m, maps_bytes):
        n, self.threads = rows_in_flight(lambda lights: self.band_rows(w, h, lights, maps_bytes), m, h, self.given)
        return n

    def said(self, tiles):
        """The note's words for it ("two at a time, " or "")."""
        if self.threads == 1 or tiles == 1:
            return ""
        return f"{'two' if self.threads == 2 else self.threads} at a time, "


def in_order_on_threads(fn, calls, threads):
    """fn(*args) for each args of `calls`, at most `threads` running at once, the results in the
    order of `calls` (each yielded as soon as it and those before it are done)."""
    with ThreadPoolExecutor(threads, thread_name_prefix="band") as pool:
        running = deque()
        for args in calls:
            running.append(pool.submit(fn, *args))
            if len(running) >= threads:
                yield running.popleft().result()
        while running:
            yield running.popleft().result()
