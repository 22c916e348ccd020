"""facewrap.parallel: how many threads, answers in order, background work."""

from __future__ import annotations

import threading

import pytest

from facewrap import parallel


@pytest.mark.parametrize("cap, expected", [("1", 1), ("0", None), ("x", None), ("", None)])
def test_threads_follow_omp_num_threads_when_it_is_a_positive_integer(monkeypatch, cap,
                                                                      expected):
    monkeypatch.setattr(parallel, "usable_cores", lambda: 4)
    monkeypatch.setenv("OMP_NUM_THREADS", cap)
    assert parallel.usable_threads() == (4 if expected is None else expected)


def test_thread_map_keeps_order_and_uses_other_threads(monkeypatch):
    monkeypatch.setattr(parallel, "usable_threads", lambda: 2)
    barrier = threading.Barrier(2, timeout=10)

    def meet(x):          # two calls must run at once to pass the barrier
        barrier.wait()
        return x, threading.current_thread().name

    out = parallel.thread_map(meet, [1, 2])
    assert [x for x, _ in out] == [1, 2]
    assert all(name.startswith("facewrap") for _, name in out)


def test_thread_map_raises_the_first_failure_in_order():
    def f(x):
        if x:
            raise ValueError(f"bad {x}")
        return x
    with pytest.raises(ValueError, match="bad 1"):
        parallel.thread_map(f, [0, 1, 2], threads=2)
