"""The filter kernels' argument bundles: named tuples of arrays and settings.

numba takes a ``NamedTuple`` as one typed argument, so a call site names what it passes instead
of lining up a dozen positional values: ``kalman_step`` takes the first three,
``filter_step`` (a whole Kalman-mode frame) all but ``KalmanFrame``, which it builds itself. The
arrays are the caller's own (a kernel changes some in place, as its docstring says). Shapes:
``S`` slots, ``n`` rows of the frame, ``J`` joints, ``L`` links.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "FrameRows",
    "KalmanFrame",
    "KalmanModel",
    "KalmanState",
    "LengthState",
    "LinkEnds",
    "OrientationState",
    "TrackStamps",
]


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


class TrackStamps(NamedTuple):
    """The frame's tracks: their slots and when they last stepped (changed in place)."""

    rows: np.ndarray  # (n,) slot of each row
    time_ns: np.ndarray  # (S,) each slot's last stamp (ns)
    joint_time_ns: np.ndarray  # (S, J) each joint's last stamp in the input (ns)
    max_gap_ns: int  # a joint absent longer than this restarts (ns)


class FrameRows(NamedTuple):
    """The frame's input rows, which the kernel turns into its output rows in place."""

    markers: np.ndarray  # (n, J, 20) marker rows
    present: np.ndarray  # (n, J) which joints are present
    stamps: np.ndarray  # (n,) each row's stamp (ns)


class LengthState(NamedTuple):
    """Whether and how link lengths are kept (``LengthKeeper``)."""

    keep: bool  # project the states onto the input's held link lengths
    parents: np.ndarray  # (J,) the layout's tree (``KinematicTree.parents``)
    order: np.ndarray  # (J,) parents before children (``KinematicTree.order``)
    last_lengths: np.ndarray  # (S, J) each slot's input lengths of its last frame (changed)


class OrientationState(NamedTuple):
    """The tracks' smoothed orientations and angular rates (changed in place)."""

    quaternions: np.ndarray  # (S, J, 4) x, y, z, w
    velocities: np.ndarray  # (S, J, 3) angular velocities (rad/s)
    accelerations: np.ndarray  # (S, J, 3) angular accelerations (rad/s^2)
    cutoff: float  # the slerp smoothing's cutoff frequency (Hz)


class LinkEnds(NamedTuple):
    """The layout's links (``Layout.link_parents``, ``Layout.link_children``)."""

    parents: np.ndarray  # (L,) joint each link starts at
    children: np.ndarray  # (L,) joint each link ends at
