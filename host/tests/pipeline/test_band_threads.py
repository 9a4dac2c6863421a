"""pipeline._band_threads: two bands solved at once, their results in order, their rows from the budget
of one band of twice the photographs."""
import threading
import time

import pytest

from facette.pipeline import _band_threads
from facette.pipeline._band_threads import InFlight, in_order_on_threads, rows_in_flight


def test_results_come_in_the_calls_order_with_at_most_threads_at_once():
    running, most, lock = [0], [0], threading.Lock()

    def fn(i, wait):
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        time.sleep(wait)                   # the later calls finish first
        with lock:
            running[0] -= 1
        return i
    calls = [(i, 0.02 * (6 - i)) for i in range(6)]
    assert list(in_order_on_threads(fn, calls, 2)) == list(range(6))
    assert most[0] == 2


def test_an_error_in_a_band_reaches_the_caller():
    def fn(i):
        if i == 1:
            raise ValueError("band 1")
        return i
    with pytest.raises(ValueError, match="band 1"):
        list(in_order_on_threads(fn, [(0,), (1,), (2,)], 2))


def test_rows_are_the_budgets_for_twice_the_photographs(monkeypatch):
    monkeypatch.setattr(_band_threads.os, "cpu_count", lambda: 2)
    budget_rows = lambda lights: 6000 // lights                  # noqa: E731  (rows inverse to the photographs)
    assert rows_in_flight(budget_rows, 60, 4000, given=False) == (50, 2)
    assert rows_in_flight(budget_rows, 60, 4000, given=True) == (100, 1)      # rows given: as given
    assert rows_in_flight(budget_rows, 60, 40, given=False) == (100, 1)       # one band: one at a time


def test_one_band_at_a_time_where_two_do_not_fit_or_one_core(monkeypatch):
    def fits_one(lights):
        if lights > 60:
            raise ValueError("too small")
        return 10
    monkeypatch.setattr(_band_threads.os, "cpu_count", lambda: 2)
    assert rows_in_flight(fits_one, 60, 4000, given=False) == (10, 1)
    monkeypatch.setattr(_band_threads.os, "cpu_count", lambda: 1)
    assert rows_in_flight(lambda lights: 100, 60, 4000, given=False) == (100, 1)


def test_in_flight_remembers_its_choice_and_says_it(monkeypatch):
    monkeypatch.setattr(_band_threads.os, "cpu_count", lambda: 8)
    flight = InFlight(lambda w, h, lights, maps_bytes: 12000 // lights, given=False)
    assert flight.rows_for(100, 4000, 60, 0) == 100 and flight.threads == 2
    assert flight.said(40) == "two at a time, " and flight.said(1) == ""
