"""Numba's compilation is timed apart: the CompileTimer counts a fresh compilation once, however nested."""
import numpy as np
from numba import njit

from experiments.compile_time import CompileTimer


def test_a_compilation_is_counted_once_and_a_second_call_adds_nothing():
    @njit
    def inner(x):
        return x * 2.0

    @njit
    def outer(x):
        return inner(x) + 1.0

    with CompileTimer() as t:
        assert outer(np.float64(1.0)) == 3.0
        first = t.seconds
        assert first > 0 and len(t._spans) == 1  # inner compiled inside outer: one span
        outer(np.float64(2.0))
        assert t.seconds == first
    with CompileTimer() as later:
        outer(np.float64(3.0))
    assert later.seconds == 0.0
