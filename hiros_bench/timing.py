"""Timing helper shared by the benchmarks: best-of-repeats per call, robust on a noisy machine."""

from __future__ import annotations

import time
from collections.abc import Callable


def per_call_seconds(
    function: Callable[[], object], *, repeats: int = 5, budget: float = 0.3
) -> float:
    """Seconds per call of ``function``: the best of ``repeats`` batches of about ``budget`` s.

    The minimum over batches is the figure least disturbed by other processes on a shared
    machine; each batch size is calibrated so that timer resolution does not matter.
    """
    function()
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < budget / repeats:
        function()
        calls += 1
    calls = max(calls, 1)
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            function()
        best = min(best, (time.perf_counter() - start) / calls)
    return best
