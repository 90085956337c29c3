"""The tracker kernels' argument bundles: named tuples of arrays and settings.

numba takes a ``NamedTuple`` as one typed argument and reads its fields by name inside a
kernel, so a call site names what it passes instead of lining up two dozen positional values.
The arrays in a bundle are the caller's own (a kernel changes some in place, as its docstring
says); the bundles themselves are never changed. Shapes as in ``tracker.py``: ``T`` tracks,
``D`` detections, ``U`` matched pairs, ``J`` joints, ``K`` mirror parts, ``C`` cameras.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "FacingBody",
    "FacingPriors",
    "FacingView",
    "FrameRows",
    "GateFrame",
    "GateSettings",
    "GateTracks",
    "HeldSides",
    "HitLayout",
    "HitSettings",
    "Hits",
    "MatchSettings",
    "MirrorLayout",
    "SideLayout",
    "StackedRows",
    "TrackFields",
    "TrackPoses",
    "UpdateSettings",
]


class MirrorLayout(NamedTuple):
    """A layout's left/right structure (``_MirrorParts``)."""

    part: np.ndarray  # (J,) mirror part of each joint, -1 on the midline
    mirror: np.ndarray  # (J,) the left/right permutation
    n_parts: int  # K


class TrackPoses(NamedTuple):
    """What the association cost needs of each track."""

    positions: np.ndarray  # (T, J, 3) poses
    velocity: np.ndarray  # (T, 3) body velocities (m/s)
    time_ns: np.ndarray  # (T,) the poses' times


class MatchSettings(NamedTuple):
    """How detections are compared with tracks (``match_costs``)."""

    max_prediction: float  # longest prediction either way (s)
    use_parts: bool  # compare each mirror part also mirrored
    min_joints: int  # fewest shared joints for a finite cost
    margin: float  # how much cheaper (m) a part's mirror must be


class GateTracks(NamedTuple):
    """What the gate needs of each track (``TrackTable`` fields)."""

    last_hit_ns: np.ndarray  # (T,)
    confirmed: np.ndarray  # (T,)
    body_ids: np.ndarray  # (T, C) the body id each camera gave the track last
    seen: np.ndarray  # (T, C) whether the camera has seen it


class GateFrame(NamedTuple):
    """The frame the gate judges."""

    det_ids: np.ndarray  # (D,) the camera's body ids of the detections
    camera: int  # the camera's code (column of body_ids)
    stamp_ns: int  # the frame's stamp
    recent_ns: int  # tracks hit since then are the cascade's first level


class GateSettings(NamedTuple):
    """The gate's settings (``gate_costs``)."""

    bonus: float  # body-id evidence (m); 0: none
    distance: float  # gate (m) of a track just hit
    growth: float  # gate widening (m/s) while unseen


class SideLayout(NamedTuple):
    """Left/right pairs held to the shoulders' side (``_side_arrays``)."""

    shoulders: np.ndarray  # (2,) left and right shoulder, or empty
    pairs: np.ndarray  # (P, 2) left and right top joint of each other part
    pair_parts: np.ndarray  # (P,) each pair's mirror part
    below: np.ndarray  # (Q, 2) left and right joints below those tops (knees, ankles, feet)
    below_parts: np.ndarray  # (Q,) each of those pairs' mirror part


class HeldSides(NamedTuple):
    """The tracks a frame's detections are held to (``_reversed_sides``)."""

    tracks: np.ndarray  # (T, J, 3) the tracks' poses
    axes: np.ndarray  # (T, 3) the tracks' held left-right axes (0: none yet, the pose's)
    velocity: np.ndarray  # (T, 3) the tracks' body velocities, m/s
    track_rows: np.ndarray  # (U,) each detection's track row
    left: np.ndarray  # (2,) left shoulder and hip; empty: sides not held
    right: np.ndarray  # (2,) right shoulder and hip
    camera_axes: np.ndarray  # (T, C, 3) each camera's last detection's axis (0: none)
    camera_ns: np.ndarray  # (T, C) its stamp
    camera: int  # the frame's camera code
    stamp_ns: int  # the frame's stamp
    facing: np.ndarray  # (T,) the tracks' log-odds that their sides are right (``facing``)


class TrackFields(NamedTuple):
    """The ``TrackTable`` fields the frame kernels read and change in place."""

    positions: np.ndarray  # (T, J, 3)
    velocities: np.ndarray  # (T, J, 3) joint velocities
    velocity: np.ndarray  # (T, 3) body velocity
    time_ns: np.ndarray  # (T,) the poses' times
    last_hit_ns: np.ndarray  # (T,)
    epoch_ns: np.ndarray  # (T,) time origin of the running sums
    hits: np.ndarray  # (T,)
    n_cameras: np.ndarray  # (T,) one more than the highest camera code that saw the track
    body_ids: np.ndarray  # (T, C)
    seen: np.ndarray  # (T, C)
    sums: np.ndarray  # (T, C, J, 9) running least-squares sums per camera
    record_ns: np.ndarray  # (T, R) ring of the velocity window's detections: stamps
    record_camera: np.ndarray  # (T, R) their cameras
    record_terms: np.ndarray  # (T, R, J, 9) their least-squares terms
    record_start: np.ndarray  # (T,) ring start
    record_count: np.ndarray  # (T,) ring length
    facing: np.ndarray  # (T,) log-odds that the track's sides are right
    facing_ns: np.ndarray  # (T,) when ``facing`` was set
    doubt: np.ndarray  # (T,) the cameras' evidence against the sides while walking backwards
    # (``facing.DOUBT_LIMIT``)
    sides: np.ndarray  # (T, 3) held left-right axis, m (``labels.hold_axes``; 0: none yet)
    camera_sides: np.ndarray  # (T, C, 3) each camera's last detection's axis, as labelled
    camera_sides_ns: np.ndarray  # (T, C) its stamp
    camera_verdicts: np.ndarray  # (T, C) each camera's last view evidence on the sides
    camera_verdicts_ns: np.ndarray  # (T, C) its stamp (0: none)
    confirmed: np.ndarray  # (T,)
    ids: np.ndarray  # (T,)


class Hits(NamedTuple):
    """One frame's detections folded into their tracks (``fold_hits``)."""

    rows: np.ndarray  # (U,) distinct track rows
    canonical: np.ndarray  # (U, J, 3) their detections in their labelling
    det_ids: np.ndarray  # (U,) the camera's body ids of the detections
    camera: int
    stamp_ns: int


class UpdateSettings(NamedTuple):
    """How a hit updates its track (``fold_hits``)."""

    smoothing: float  # share of the way to the detection (1 on a track's first hit)
    max_prediction: float  # longest prediction (s)
    window_ns: int  # velocity window
    weights: np.ndarray  # (J,) joint weights of the body velocity


class FacingBody(NamedTuple):
    """Joints of a body's frame (``_BodyFrame``) and the mirror permutation."""

    root: int
    neck: int
    left: np.ndarray  # (2,) left shoulder and hip
    right: np.ndarray  # (2,) right shoulder and hip
    pointers: np.ndarray  # (k, 2) joint pairs pointing forward
    mirror: np.ndarray  # (J,)


class FacingPriors(NamedTuple):
    """The facing check's settings (``TrackerParams`` of the same names)."""

    flip_prior: float
    flip_prior_back: float
    walking_speed: float
    walking_evidence: float
    facing_memory: float  # s
    facing_memory_standing: float  # s
    facing_threshold: float


class FacingView(NamedTuple):
    """Where a frame's facing is judged from."""

    up: np.ndarray  # (4,) the world's up and whether it is known (``_update_up``; in place)
    camera_position: np.ndarray  # (3,) used when ``has_camera``
    has_camera: bool
    camera: int  # the camera's code
    stamp_ns: int


class StackedRows(NamedTuple):
    """A frame's detections' rows, labelled in place (``SkeletonRows``' first four fields)."""

    markers: np.ndarray  # (N, J, 20)
    present: np.ndarray  # (N, J)
    links: np.ndarray  # (N, J, 20)
    link_present: np.ndarray  # (N, J)


class FrameRows(NamedTuple):
    """A frame's detections as the tracker sees them (``hit_frame``)."""

    positions: np.ndarray  # (D, J, 3) masked positions
    det_ids: np.ndarray  # (D,) body ids
    index: np.ndarray  # (D,) their rows in ``stacked``
    stacked: StackedRows


class HitLayout(NamedTuple):
    """What ``hit_frame`` needs of the layout."""

    mirror: MirrorLayout
    sides: SideLayout
    body: FacingBody


class HitSettings(NamedTuple):
    """What ``hit_frame`` does with a frame."""

    update: UpdateSettings
    align: bool  # hold hips, eyes, ears and the body's sides to the shoulders and the track
    weigh: bool  # weigh the facing
    label: bool  # label the output detections when every track hit is confirmed
    priors: FacingPriors
