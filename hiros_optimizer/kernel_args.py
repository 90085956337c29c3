"""The optimizer kernels' argument bundles: named tuples of arrays and settings.

numba takes a ``NamedTuple`` as one typed argument, so a call site names what it passes instead
of lining up twenty positional values. The kernels unpack the bundles by position (the tuples
they build for their inner calls are plain tuples in the same field order). The arrays are the
caller's own (a kernel changes some in place, as its docstring says). Shapes: ``P`` people of
the frame, ``S`` memory rows, ``J`` joints.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["FitSettings", "FitTree", "FrameRows", "MemoryState"]


class FitTree(NamedTuple):
    """The kinematic tree's tables (``KinematicTree``)."""

    parents: np.ndarray  # (J,) parent of each joint, -1 at the root
    order: np.ndarray  # (J,) joints, parents before children
    level_starts: np.ndarray  # where each depth starts in ``order``


class FrameRows(NamedTuple):
    """A frame's people (``markers`` are the output rows, changed in place by the fit)."""

    markers: np.ndarray  # (P, J, 20) marker rows
    present: np.ndarray  # (P, J) which joints are present
    rows: np.ndarray  # (P,) each person's memory row
    stamps: np.ndarray  # (P,) their times (ns)


class MemoryState(NamedTuple):
    """``Memory``'s per-row motion (changed in place)."""

    time_ns: np.ndarray  # (S,) time of each row's last output
    timed: np.ndarray  # (S,) False: no motion known
    positions: np.ndarray  # (S, J, 3) last output positions
    velocities: np.ndarray  # (S, J, 3) from the last two outputs
    vectors: np.ndarray  # (S, J, 3) last fitted link vectors


class FitSettings(NamedTuple):
    """``memory.FitSettings`` typed as the kernels expect."""

    floor: float  # confidence floor of a present joint's weight
    threshold: float  # relative link-length error that makes a link's ends suspect
    distance: float  # distance (m) from the prior beyond which a suspect joint loses weight
    prior_weight: float  # weight of the motion prior
    timeout: float  # seconds after which a memory row is forgotten
    sweeps: int  # coordinate-descent sweeps
    refinements: int  # Gauss-Newton refinements
