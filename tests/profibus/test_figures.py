"""The Profibus figures' window: its median is the median of the last samples, exactly."""

from __future__ import annotations

import math
import statistics

from hypothesis import given
from hypothesis import strategies as st

from adapters.profibus.master.figures import Samples

DURATIONS = st.floats(min_value=0.0, max_value=10.0, allow_nan=False)


@given(st.integers(min_value=1, max_value=12), st.lists(DURATIONS, max_size=60))
def test_the_median_is_that_of_the_last_samples(size: int, values: list[float]) -> None:
    s = Samples(size)
    for n, value in enumerate(values, 1):
        s.add(value)
        window = values[max(0, n - size) : n]
        assert s.median == statistics.median(window)
        assert (s.count, s.last, s.min, s.max) == (n, value, min(values[:n]), max(values[:n]))


def test_repeated_values_leave_the_window_one_at_a_time() -> None:
    s = Samples(3)
    for value in (1.0, 1.0, 5.0, 5.0, 5.0, 1.0):
        s.add(value)
    assert s.median == 5.0  # the last three: 5, 5, 1
    s.add(1.0)
    assert s.median == 1.0  # 5, 1, 1


def test_no_sample_and_a_nan() -> None:
    s = Samples()
    assert math.isnan(s.median) and s.to_json() is None
    s.add(math.nan)  # no place in an order: not taken
    assert s.count == 0 and math.isnan(s.median)
    s.add(0.002)
    assert s.to_json() == {"last": 2.0, "min": 2.0, "median": 2.0, "max": 2.0}
