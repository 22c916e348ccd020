"""Timing helper shared by the benchmarks."""

from __future__ import annotations

import time


def best_of(fn, repeats: int = 3):
    """``(seconds, result)``: the fastest of ``repeats`` calls of ``fn()`` and the
    last call's result."""
    best, out = float("inf"), None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out
