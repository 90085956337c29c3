"""A node's health over time: what happened recently, its rates and its processing latency.

``HirosNode`` keeps cumulative counters (every frame accounted for since start); a diagnostic
level that followed them would turn WARN at the first dropped frame and stay so for good. The
level follows what happened in the last ``window`` seconds instead: a node is OK again after a
clean minute, and the totals stay in the values.
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Mapping

import numpy as np

__all__ = ["NodeHealth"]


class NodeHealth:
    """Snapshots of a node's cumulative counters, and the durations of its callbacks.

    Args:
        window: seconds over which the diagnostic level looks back.
        rate_window: seconds over which rates are measured.
        latencies: how many of the latest callback durations the percentiles are taken over.

    """

    def __init__(
        self, window: float = 60.0, rate_window: float = 10.0, latencies: int = 1000
    ) -> None:
        self.window = window
        self.rate_window = rate_window
        self._times: deque[float] = deque()
        self._snapshots: deque[dict[str, int]] = deque()
        self._durations: deque[float] = deque(maxlen=latencies)

    def sample(self, now: float, totals: Mapping[str, int]) -> None:
        """Keep the totals at ``now`` (s, monotonic); older ones than the window are let go."""
        self._times.append(now)
        self._snapshots.append(dict(totals))
        while len(self._times) > 2 and self._times[1] <= now - self.window:
            self._times.popleft()  # (the oldest one at or before the window's start stays)
            self._snapshots.popleft()

    def _since(self, seconds: float) -> tuple[float, dict[str, int]]:
        """The time and totals of the last snapshot at least ``seconds`` old (else the first)."""
        now = self._times[-1]
        index = bisect.bisect_right(self._times, now - seconds) - 1
        index = max(index, 0)
        return self._times[index], self._snapshots[index]

    def recent(self, key: str) -> int:
        """How much ``key`` rose over the window (all of it while the node is younger)."""
        if not self._times:
            return 0
        if self._times[0] > self._times[-1] - self.window:  # younger: everything since start
            return self._snapshots[-1].get(key, 0)
        _, then = self._since(self.window)
        return self._snapshots[-1].get(key, 0) - then.get(key, 0)

    def rate(self, key: str) -> float:
        """``key``'s rise per second over the rate window (0 before two snapshots)."""
        if len(self._times) < 2:  # a rate needs two snapshots
            return 0.0
        then_time, then = self._since(self.rate_window)
        span = self._times[-1] - then_time
        if span <= 0:
            return 0.0
        return (self._snapshots[-1].get(key, 0) - then.get(key, 0)) / span

    def add_duration(self, seconds: float) -> None:
        """One callback's processing time."""
        self._durations.append(seconds)

    def latency_ms(self) -> dict[str, float]:
        """``p50``, ``p90``, ``p99`` and ``max`` of the latest durations, in milliseconds."""
        if not self._durations:
            return {}
        values = np.fromiter(self._durations, float) * 1e3
        p50, p90, p99 = np.percentile(values, [50, 90, 99])
        return {"p50": p50, "p90": p90, "p99": p99, "max": float(values.max())}
