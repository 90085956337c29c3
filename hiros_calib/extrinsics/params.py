"""The parameters of the pose estimation, and the method's constants.

``ExtrinsicsParams`` holds what a user may tune (the node's parameters of the same names);
the constants below are the method's statistical and numerical choices.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

from hiros_calib.signature import DEFAULT_JOINTS

__all__ = [
    "ASSOCIATION_FRAMES",
    "FRAME_OUTLIER_RATIO",
    "FULL_SAMPLING",
    "INLIER_SIGMAS",
    "INLIER_THRESHOLD",
    "JOINT_OFFSET_ROUNDS",
    "LOSS",
    "MAX_CORRESPONDENCES",
    "MAX_INTERPOLATION_GAP",
    "MAX_SIGNATURE_MISMATCH",
    "MIN_COMMON_TIME",
    "MIN_CORRESPONDENCES",
    "OFFSET_SHRINKAGE",
    "QUICK_SAMPLING",
    "RANSAC_CHECKS",
    "SEED",
    "ExtrinsicsParams",
    "Sampling",
]


ASSOCIATION_FRAMES: int = 300
"""Common instants (evenly subsampled) over which two tracks' signatures are compared."""

INLIER_SIGMAS: float = 3.0
"""Inliers lie within this many robust residual scales (median residual / 1.54)."""

FRAME_OUTLIER_RATIO: float = 2.5
"""Frames whose median residual exceeds this times the typical one are left out (an
SDK that took the back for the front moves every limb)."""

RANSAC_CHECKS: int = 1000
"""Correspondences (random) each RANSAC sample is scored on."""

JOINT_OFFSET_ROUNDS: int = 3
"""Rounds of estimating the fixed per-person, per-joint disagreement between two
cameras' SDKs alternately with the poses (0: assume the SDKs agree on average)."""

OFFSET_SHRINKAGE: float = 30.0
"""Samples' worth of pull towards 0 on each joint offset, so short tracks stay sane."""

LOSS: str = "soft_l1"
"""Robust loss of the refinements, on the length of each joint's 3D residual (one of
:func:`~hiros_calib.extrinsics.robust.loss_weights`' losses)."""

MAX_INTERPOLATION_GAP: float = 0.1
"""Camera b's frames around an instant must be closer than this (s) to interpolate."""

MAX_CORRESPONDENCES: int = 200000
"""Joint correspondences per camera pair kept for the refinements (evenly subsampled): every
joint of the frames kept; on the simulator, keeping a fifth of them gave about 6 % more
rotation error."""

MIN_CORRESPONDENCES: int = 30
"""Fewer usable correspondences than this and the pair gives no pose."""

SEED: int = 0
"""Random seed of RANSAC, so that a recording always gives the same calibration."""


MAX_SIGNATURE_MISMATCH: float = 0.1
"""Largest median signature difference (m) for two tracks to be the same person."""

MIN_COMMON_TIME: float = 2.0
"""Two tracks must be seen together this long (s) to be paired (short ghosts are not)."""

INLIER_THRESHOLD: float = 0.25
"""Largest distance (m) for a joint correspondence to count as an inlier; the working
threshold adapts to the data's spread (``INLIER_SIGMAS`` times the robust scale)."""


class Sampling(NamedTuple):
    """How much of a camera pair's data one pose estimate draws on."""

    ransac_iterations: int
    """Minimal samples tried."""
    frames_per_minute: float
    """Frames (body pairs at one instant) kept per minute of recording, evenly subsampled.
    The SDKs' errors are correlated over about 0.2 s, so at 30 Hz neighbouring frames add
    little; a count that grows with the recording still uses a long one."""
    max_frames: int
    """At most this many frames, whatever the length (bounds the cost)."""


FULL_SAMPLING = Sampling(ransac_iterations=400, frames_per_minute=1000.0, max_frames=10000)
"""A calibration's pose estimates (figures behind the frame budget: docs/pose-accuracy.md)."""

QUICK_SAMPLING = Sampling(ransac_iterations=120, frames_per_minute=300.0, max_frames=1500)
"""The quick checks' fits: each candidate lag's, and each split half's."""


@dataclass
class ExtrinsicsParams:
    """Parameters of the pose estimation (same names as the ``calib`` node's)."""

    joints: list[str] = field(default_factory=lambda: list(DEFAULT_JOINTS))
    """Joints whose distances identify a person across cameras (see signature.py)."""
    pose_joints: list[str] = field(default_factory=list)
    """Joints used as correspondences; empty = every joint of the layout (more joints
    average out more of the SDK's fixed per-joint errors)."""
