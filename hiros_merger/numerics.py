"""Scalar helpers of the fusion kernels that round exactly as numpy's array forms do.

The fusion kernels reproduce numpy's results bit for bit where the outputs depend on it: a
mean over joints is summed in numpy's pairwise order, a power is rounded as numpy's array
power rounds it. The helpers take scalars (a slice taken in a kernel's inner loop costs a
reference count each time) and are inlined where they are called (``inline="always"``): a
call per joint and camera made the fusion kernel a sixth slower.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["finite3", "n_groups", "pairwise_sum", "power", "unit3"]


@njit(cache=True, error_model="numpy")
def pairwise_sum(values: np.ndarray, n: int) -> float:
    """Sum of ``values[:n]`` in numpy's order for a contiguous reduction (n <= 128)."""
    if n < 8:
        total = 0.0
        for i in range(n):
            total += values[i]
        return total
    r = values[:8].copy()
    i = 8
    while i < n - n % 8:
        for k in range(8):
            r[k] += values[i + k]
        i += 8
    total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        total += values[i]
        i += 1
    return total


@njit(cache=True, error_model="numpy", inline="always")
def power(x: float, exponent: float) -> float:
    """``x ** exponent`` as numpy's array power rounds it (squares exactly, 1 as is)."""
    if exponent == 2.0:
        return x * x
    if exponent == 1.0:
        return x
    return math.pow(x, exponent)


@njit(cache=True, error_model="numpy", inline="always")
def unit3(x: float, y: float, z: float) -> tuple[float, float, float]:
    """``(x, y, z) / |(x, y, z)|`` (NaN for the zero vector)."""
    norm = math.sqrt(x * x + y * y + z * z)
    return x / norm, y / norm, z / norm


@njit(cache=True, error_model="numpy", inline="always")
def finite3(x: float, y: float, z: float) -> bool:
    """Whether ``x``, ``y`` and ``z`` are all finite (scalars: no array view in a hot loop)."""
    return math.isfinite(x) and math.isfinite(y) and math.isfinite(z)


@njit(cache=True, error_model="numpy")
def n_groups(groups: np.ndarray) -> int:
    """How many limbs ``groups`` ``(J,)`` numbers (one more than the highest)."""
    count = 0
    for j in range(len(groups)):
        count = max(count, groups[j] + 1)
    return count
