"""Two halves of a recording's time, and how far apart two poses lie.

A pose solved on each half tells how much the data, not the method, moves it
(:func:`~hiros_calib.extrinsics.joint.solve_poses`' check, and :mod:`~hiros_calib.lags`'
cross-validated lag fit).
"""

from __future__ import annotations

import math

import numpy as np

from hiros_core.geometry import RigidTransform

__all__ = ["SPLIT_BLOCK", "relative_error", "second_half"]

SPLIT_BLOCK = 2.0
"""Length (s) of the alternating spans of time that make the two halves of a pose's check
(and the two folds of a lag's cross-validated fit, :mod:`~hiros_calib.lags`): longer than
the SDKs' error correlation, so one half's frames are not near copies of the other's."""


def second_half(times: np.ndarray) -> np.ndarray:
    """Which of two halves each instant (s) falls in: alternating ``SPLIT_BLOCK`` spans."""
    return (np.floor(times / SPLIT_BLOCK).astype(np.int64) % 2).astype(bool)


def relative_error(a: RigidTransform, b: RigidTransform) -> tuple[float, float]:
    """(rotation angle in degrees, translation distance in metres) between two poses."""
    angle = math.degrees((a.rotation.inv() * b.rotation).magnitude())
    return angle, float(np.linalg.norm(a.translation - b.translation))
