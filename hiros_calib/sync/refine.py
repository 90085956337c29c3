"""The sub-frame lag: the pooled correlation of spline-interpolated signatures, maximised.

Both signatures are evaluated on one fine grid, so neither stream's sample instants are
favoured and 30 Hz streams give millisecond offsets; the same search in sliding windows
gives the lag over time (the drift).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from scipy.interpolate import make_interp_spline
from scipy.optimize import minimize_scalar

from hiros_calib.signature import PoseSignature
from hiros_calib.sync.correlation import resample
from hiros_calib.sync.params import GRID_STEP, MAX_DRIFT, MIN_OVERLAP, SyncParams

__all__ = ["RefinePair", "Spline", "lag_windows", "refine", "window_edges"]


@dataclass
class Spline:
    """A track's mean-free signature as a cubic spline, with weights on a grid.

    ``values`` is evaluated at arbitrary (shifted) times; ``weights`` are tabulated every
    ``step`` from ``start`` and looked up by nearest sample, which is plenty for weights and
    much cheaper than interpolating them at every trial lag (see :meth:`weights_from`).
    """

    start: float
    end: float
    step: float
    values: Any
    weights: np.ndarray  # (N, C) on start + k * step

    @classmethod
    def build(cls, signature: PoseSignature, step: float) -> Spline:
        """The mean-free signature's cubic spline and its weights every ``step`` s."""
        times, weights = signature.times, signature.weights
        total = weights.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(total > 0, np.nansum(signature.values * weights, axis=0) / total, 0.0)
        centred = np.where(weights > 0, signature.values - mean, 0.0)
        spline = make_interp_spline(times, centred, k=3)
        grid = np.arange(times[0], times[-1], step)
        return cls(float(times[0]), float(times[-1]), step, spline, resample(times, weights, grid))

    def weights_from(self, t0: float, count: int) -> np.ndarray:
        """Weights at ``t0 + k * step`` for ``k < count`` (nearest sample, clamped at the ends).

        The trial instants share the tabulation's step, so this is a slice, not a gather.
        """
        first = round((t0 - self.start) / self.step)
        if first >= 0 and first + count <= len(self.weights):
            return self.weights[first : first + count]
        index = np.clip(np.arange(first, first + count), 0, len(self.weights) - 1)
        return self.weights[index]

    @cached_property
    def tabulated(self) -> tuple[np.ndarray, np.ndarray]:
        """``(N,)`` the weight grid's times and ``(N, C)`` the values there."""
        times = self.start + np.arange(len(self.weights)) * self.step
        return times, self.values(times)


@dataclass
class RefinePair:
    """One body pair prepared for the continuous lag search: a tabulated on its own grid."""

    a: Spline
    b: Spline
    times: np.ndarray  # (N,) a's grid
    values: np.ndarray  # (N, C) a's signature there
    weights: np.ndarray  # (N, C)

    @classmethod
    def build(cls, a: Spline, b: Spline) -> RefinePair:
        """The pair with a tabulated on its weight grid."""
        times, values = a.tabulated
        return cls(a, b, times, values, a.weights)

    def sums(self, tau: float, span: tuple[float, float]) -> tuple[float, float, float]:
        """Weighted covariance and variances (summed over channels) with b shifted by ``tau``.

        Means are taken over the common part only, per channel, so tracks covering different
        stretches of a walk do not bias the lag.
        """
        lo = max(self.b.start + tau, span[0])
        hi = min(self.b.end + tau, span[1])
        i0, i1 = np.searchsorted(self.times, [lo, hi])
        if i1 - i0 < 4:
            return 0.0, 0.0, 0.0
        t = self.times[i0:i1]
        w = self.weights[i0:i1] * self.b.weights_from(float(t[0]) - tau, i1 - i0)
        va, vb = self.values[i0:i1], self.b.values(t - tau)
        # sum w (a - mean_a)(b - mean_b) = sum w a b - (sum w a)(sum w b) / sum w, per channel
        total = np.maximum(w.sum(axis=0), 1e-12)
        wa, wb = w * va, w * vb
        sum_a, sum_b = wa.sum(axis=0), wb.sum(axis=0)
        sab = np.einsum("nc,nc->c", wa, vb) - sum_a * sum_b / total
        saa = np.einsum("nc,nc->c", wa, va) - sum_a * sum_a / total
        sbb = np.einsum("nc,nc->c", wb, vb) - sum_b * sum_b / total
        return float(sab.sum()), float(saa.sum()), float(sbb.sum())

    def overlap(self, tau: float, span: tuple[float, float]) -> float:
        """Seconds of common data with b shifted by ``tau`` inside ``span``."""
        lo = max(self.a.start, self.b.start + tau, span[0])
        hi = min(self.a.end, self.b.end + tau, span[1])
        return max(0.0, hi - lo)


def _pooled_correlation(tau: float, pairs: list[RefinePair], span: tuple[float, float]) -> float:
    """Correlation of all body pairs' signatures with b shifted by ``tau``.

    Both signatures are cubic-spline interpolants evaluated on one grid of a's clock (b at
    ``t - tau``); ``span`` limits the grid for windowed estimates.
    """
    sums = np.array([pair.sums(tau, span) for pair in pairs]).sum(axis=0)
    if sums[1] <= 0 or sums[2] <= 0:
        return 0.0
    return float(sums[0] / math.sqrt(sums[1] * sums[2]))


def refine(
    tau0: float,
    half_width: float,
    pairs: list[RefinePair],
    span: tuple[float, float] = (-math.inf, math.inf),
) -> tuple[float, float]:
    """The lag in ``tau0 ± half_width`` maximising the pooled correlation, and that value."""
    result = minimize_scalar(
        lambda tau: -_pooled_correlation(tau, pairs, span),
        bounds=(tau0 - half_width, tau0 + half_width),
        method="bounded",
        options={"xatol": 2e-5},
    )
    return float(result.x), float(-result.fun)


def window_edges(start: float, end: float, width: float) -> list[tuple[float, float]]:
    """``[start, end]`` cut into equal windows of about ``width`` s (at least one)."""
    count = max(1, round((end - start) / width))
    return list(itertools.pairwise(np.linspace(start, end, count + 1).tolist()))


def lag_windows(tau: float, pairs: list[RefinePair], params: SyncParams) -> np.ndarray:
    """Lag measured in sliding windows of a's clock: rows (t_b centre, tau, weight, corr)."""
    start = min(max(p.a.start, p.b.start + tau) for p in pairs)
    end = max(min(p.a.end, p.b.end + tau) for p in pairs)
    span = end - start
    edges = window_edges(start, end, params.window)
    half_width = 2 * GRID_STEP + MAX_DRIFT * span
    rows = []
    for lo, hi in edges:
        overlap = sum(p.overlap(tau, (lo, hi)) for p in pairs)
        if overlap < min(MIN_OVERLAP, 0.5 * (hi - lo)):
            continue
        value, corr = refine(tau, half_width, pairs, (lo, hi))
        if corr < params.min_peak:
            continue
        rows.append((0.5 * (lo + hi) - value, value, overlap * corr**2, corr))
    return np.array(rows).reshape(-1, 4)
