"""The fusion kernels' argument bundles: named tuples of arrays and settings.

numba takes a ``NamedTuple`` as one typed argument and reads its fields by name inside a
kernel, so a call site names what it passes instead of lining up two dozen positional values
in an order two files must agree on. The arrays in a bundle are the caller's own; the bundles
themselves are never changed. Shapes as in ``merger.py``: ``S`` stored slots, ``K`` cameras,
``M`` tracks, ``C`` detections per track (padded), ``J`` joints of the layout (``J' >= J``
the store's joint columns).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "BodyLayout",
    "CameraTable",
    "FuseSettings",
    "Fusion",
    "MergedFrame",
    "Observations",
    "RobustSettings",
    "StoredDetections",
    "TrackDetections",
    "WeightSettings",
]


class StoredDetections(NamedTuple):
    """The merger's store (``LatestDetections``): each track's newest detection per camera."""

    rows: np.ndarray  # (S, J', 20) marker rows of each slot
    present: np.ndarray  # (S, J') marker presence
    stamps: np.ndarray  # (S,) src_time_ns
    tracks: np.ndarray  # (S,) track ids
    cameras: np.ndarray  # (S,) camera indices


class CameraTable(NamedTuple):
    """What the fusion knows of each camera, by camera index."""

    positions: np.ndarray  # (K, 3) world positions, NaN: unknown


class TrackDetections(NamedTuple):
    """One output's detections by track: detection ``c`` of track ``m`` is ``table[m, c]``."""

    rows: np.ndarray  # (S, J', 20) the store's marker rows
    present: np.ndarray  # (S, J') the store's presence
    table: np.ndarray  # (M, C) slots, -1: padding
    ages: np.ndarray  # (M, C) seconds from the detection to the output time
    cameras: np.ndarray  # (M, C, 3) the detection's camera position, NaN: unknown


class Observations(NamedTuple):
    """Each detection's joints at the output time (``weights.detections_at``)."""

    positions: np.ndarray  # (M, C, J, 3) NaN: absent or padding
    velocities: np.ndarray  # (M, C, J, 3)
    finite: np.ndarray  # (M, C, J) whether the position is finite
    confidences: np.ndarray  # (M, C, J) SDK confidences, 1 where not finite
    weight: np.ndarray  # (M, C, J) reliability weights (the facing and occlusion factors
    #                     multiply them in place)


class BodyLayout(NamedTuple):
    """The joints of a layout that the weights and the limbs need (``merger.BodyAxes``)."""

    root: int
    neck: int  # -1: the layout has none
    left: np.ndarray  # (2,) hip and shoulder on the left
    right: np.ndarray  # (2,)
    torso: np.ndarray  # joints standing for the torso in occlusion tests
    pointers: np.ndarray  # (k, 2) joint pairs pointing forward: ankle -> foot, head -> nose
    has_front: bool  # whether the layout names what the facing direction needs
    groups: np.ndarray  # (J,) limb of each joint: 0 torso, then one per subtree off the torso
    link_parents: np.ndarray  # the layout's links' parent joints
    link_children: np.ndarray  # and child joints (= link ids)


class WeightSettings(NamedTuple):
    """The reliability weights' settings (``MergerParams``' fields, ``merger.py``'s constants)."""

    max_extrapolation: float
    confidence_floor: float
    confidence_power: float
    staleness_scale: float
    depth_gain: float
    flipped_weight: float
    oblique_gain: float
    occlusion_radius: float
    occlusion_weight: float


class RobustSettings(NamedTuple):
    """The robust mean's parameters."""

    iterations: int
    outlier_scale: float
    outlier_cutoff: float
    limb_cutoff: float


class FuseSettings(NamedTuple):
    """Every parameter of one fusion."""

    weights: WeightSettings
    robust: RobustSettings


class Fusion(NamedTuple):
    """What ``fuse`` finds for each track."""

    positions: np.ndarray  # (M, J, 3) fused
    final: np.ndarray  # (M, C, J) each detection's final weights
    confidence: np.ndarray  # (M, J) weighted mean confidences
    velocity: np.ndarray  # (M, J, 3) weighted mean velocities


class MergedFrame(NamedTuple):
    """One output of ``merge``, ready for ``SkeletonRows``."""

    track_ids: np.ndarray  # (M,) sorted
    table: np.ndarray  # (M, C) each track's slots, -1: padding
    final: np.ndarray  # (M, C, J) final weights
    rows: np.ndarray  # (M, J, 20) output marker rows
    present: np.ndarray  # (M, J)
    links: np.ndarray  # link rows (``model.link_rows``')
    link_present: np.ndarray
    confidences: np.ndarray  # (M,) skeleton confidences
    oriented: bool  # whether a selected joint has an orientation (averaged outside)
