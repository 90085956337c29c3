"""The filter kernels' argument bundles: named tuples of arrays and settings.

numba takes a ``NamedTuple`` as one typed argument, so a call site names what it passes instead
of lining up a dozen positional values. The kernels unpack the bundles by position, so
``compiled.filter_step`` hands on the plain tuples it was given in the same field order. The
arrays are the caller's own (a kernel changes some in place, as its docstring says). Shapes:
``S`` slots, ``n`` rows of the frame, ``J`` joints.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["KalmanFrame", "KalmanModel", "KalmanState"]


class KalmanState(NamedTuple):
    """The ``KalmanBank``'s state (changed in place by ``kalman_step``)."""

    x: np.ndarray  # (S, 3, 3, J) [position, velocity, acceleration] x axis of each joint
    P: np.ndarray  # (S, 3, 3, J) covariance of each joint (shared by its three axes)
    scale: np.ndarray  # (S, J) adaptive process-noise scale


class KalmanModel(NamedTuple):
    """The ``KalmanBank``'s constants."""

    q: float  # jerk spectral density (m^2/s^5)
    r: float  # measurement variance (m^2)
    max_scale: float  # the adaptive scale's ceiling (1: not adaptive)
    rate: float  # the adaptive scale's smoothing rate
    initial: np.ndarray  # (3, 3) covariance of a reset joint


class KalmanFrame(NamedTuple):
    """One step's rows: which slots advance by how long, and what corrects them."""

    rows: np.ndarray  # (n,) slot of each row
    dt: np.ndarray  # (n,) time since each slot's last step (s)
    dt_rounded: np.ndarray  # (n,) dt rounded to the µs the process noise is tabulated at
    mask: np.ndarray  # (n, J) which joints are corrected
    positions: np.ndarray  # (n, J, 3) their measured positions
