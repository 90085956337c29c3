"""Tracker: a persistent track id for every camera detection, across cameras and over time.

Data flow of ``Tracker.update`` (one call per camera frame; the node calls exactly this):

1. the camera's group is moved into the world frame and onto the reference clock
   (``CameraCorrection``);
2. it waits in a small buffer for ``max_delay`` seconds so that frames of other cameras arriving
   late can be processed before it (frames are released in reference-time order);
3. each released frame is associated with the tracks: every track is predicted to the frame's
   corrected time with a constant-velocity model (per-joint velocities fitted over the last
   ``velocity_window`` with one intercept per camera); the cost of a (track, detection) pair
   is the mean joint distance weighted towards the body's core, minus/plus ``body_id_bonus``
   where the camera's own body ids agree/disagree; pairs beyond the gate are excluded and the
   rest solved with ``scipy.optimize.linear_sum_assignment`` in a cascade (DeepSORT-like):
   confirmed tracks seen within ``recent_window`` first, then the other confirmed tracks,
   then tentative tracks with the detections left;
4. unmatched detections start tentative tracks; a tentative track is confirmed after
   ``min_hits`` hits from ``min_cameras`` cameras (or after ``single_camera_confirm`` seconds),
   unless it sits on a confirmed track (a duplicate body); tracks without hits expire.

Side swaps: the body is split into mirror parts (for the Azure Kinect layout: arms, legs, eyes,
ears — each a left/right pair of limbs hanging off the midline). For each pair and part the
cost takes the cheaper of the detection's labelling and its mirror, so a front/back flip
(everything swapped) neither breaks the match nor reaches the output: detections are relabelled
to their track's sides, and each detection's hips, eyes and ears are then put on the side of its
shoulders (undoing the SDK's leg swaps). Which way the track itself faces is weighed from every
detection (``facing_check``): a detection whose feet and nose point against the track's front is
a flip if the track is right, SDKs flip mostly when they see a person's back, and people face
where they walk; when the evidence turns against the track, the track is relabelled.

Output (Hi-ROS's): one skeleton per camera detection of a confirmed track, ``id`` = track id,
``src_frame`` = the camera's frame, ``src_time`` = the corrected stamp, world-frame poses, each
joint's velocity (m/s) filled from the track where the camera gave none.

Shapes: ``T`` tracks, ``D`` detections, ``J`` joints, ``K`` mirror parts; metres, seconds.
"""

from __future__ import annotations

import heapq
import itertools
from collections import Counter, deque
from dataclasses import dataclass
from functools import cache, cached_property

import numpy as np
from scipy.optimize import linear_sum_assignment

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.layouts import Layout
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_tracker.correction import CameraCorrection

__all__ = ["Tracker", "TrackerParams"]

_NS = 1e-9
_INFEASIBLE = 1e9
"""Cost given to gated-out pairs so that the solver still sees a full matrix."""


@dataclass
class TrackerParams:
    """Tracker parameters (field names = ROS parameter names of the ``tracker`` node).

    Attributes:
        max_delay: seconds a frame waits for late frames of other cameras before it is
            processed; frames older than the last processed one are dropped as ``late``.
        gate_distance: metres; a detection farther than this (weighted mean joint distance)
            from a track's prediction cannot be assigned to it.
        gate_growth: metres per second; the gate widens by this for each second a track went
            unseen, so that a person whose cameras dropped out can be picked up again.
        min_hits: hits a tentative track needs to be confirmed (and output).
        min_cameras: distinct cameras a tentative track must be seen by to be confirmed
            (capped at the number of calibrated cameras); one camera's ghost bodies fail it.
        single_camera_confirm: seconds after which a tentative track seen by fewer cameras is
            confirmed anyway (a person only one camera sees); longer than a ghost body lasts.
        tentative_timeout: seconds a tentative track survives without a hit.
        track_timeout: seconds a confirmed track survives without a hit.
        recent_window: seconds; confirmed tracks hit within it are matched before those that
            have gone unseen longer (a person who left must not take another's detections).
        max_prediction: seconds of constant-velocity extrapolation at most.
        position_smoothing: weight (0..1] of a new detection in the track's reference pose.
        velocity_window: seconds of history the per-joint velocities are fitted over.
        body_id_bonus: metres taken off the cost when a camera reports the body id it gave the
            track's previous detection, and added to the track's other candidates when that id
            is in the frame: a tie-breaker when two people are close, small enough that
            positions overrule a camera's own id changes and swaps.
        velocity_weight: metres of cost per m/s of velocity difference (0: positions only;
            used when detections carry velocities).
        orientation_weight: metres of cost per radian of joint orientation difference
            (0: positions only; used when detections carry orientations).
        mirror_check: compare each mirror part also with its left/right mirror and keep the
            cheaper labelling (front/back flips, side swaps).
        mirror_margin: metres (mean over a part's joints) the mirror must be cheaper by.
        mirror_vote: without the facing check (or the joints it needs), relabel a part of a
            track when most cameras currently seeing it call its sides mirrored.
        facing_check: decide which way a track faces (hence its left and right) from the
            evidence of every detection: a detection whose feet and nose point against the
            track's front is flipped if the track is right, and SDKs flip mostly when they see
            a person's back (``flip_prior_back`` against ``flip_prior``); walking forward
            adds evidence. Majorities alone fail when two of three cameras are flipped. The
            other parts (legs, eyes, ears) then take their left from the shoulders'.
        flip_prior: chance that a detection is front/back flipped when its camera sees the
            person's front or side.
        flip_prior_back: the same when the camera sees the person's back (cos < -0.5).
        facing_memory: seconds over which the facing evidence fades.
        facing_threshold: log-odds against the track's facing at which it is relabelled.
        walking_speed: m/s above which a person is taken to face where they walk.
        walking_evidence: log-odds added per detection for facing the walking direction.
        duplicate_distance: metres; a tentative track closer than this to a confirmed track
            when it would be confirmed is a duplicate body and is deleted.
        joint_weight_decay: a joint's weight in the cost is this to the power of its depth in
            the skeleton tree (pelvis 1, hips 0.5, knees 0.25, ...): the body's core places a
            person; limbs swing, get occluded and are the first a flip throws off.
        min_joints: joints a detection and a track must share for a cost to exist.
        min_confidence: joints of lower confidence are left out of the cost (the SDK's NONE
            level, 0, marks joints outside the view).

    """

    max_delay: float = 0.05
    gate_distance: float = 0.5
    gate_growth: float = 0.5
    min_hits: int = 8
    min_cameras: int = 2
    single_camera_confirm: float = 2.0
    tentative_timeout: float = 0.3
    track_timeout: float = 2.0
    recent_window: float = 0.2
    max_prediction: float = 0.5
    position_smoothing: float = 0.6
    velocity_window: float = 0.25
    body_id_bonus: float = 0.1
    velocity_weight: float = 0.0
    orientation_weight: float = 0.0
    mirror_check: bool = True
    mirror_margin: float = 0.02
    mirror_vote: bool = True
    facing_check: bool = True
    flip_prior: float = 0.1
    flip_prior_back: float = 0.7
    facing_memory: float = 3.0
    facing_threshold: float = 3.0
    walking_speed: float = 0.4
    walking_evidence: float = 0.3
    duplicate_distance: float = 0.25
    joint_weight_decay: float = 0.5
    min_joints: int = 4
    min_confidence: float = 0.1


@dataclass(frozen=True, eq=False)
class _MirrorParts:
    """A layout's left/right structure.

    Attributes:
        mirror: ``(J,)`` the layout's left/right permutation.
        part: ``(J,)`` mirror part of each joint, ``-1`` on the midline.
        onehot: ``(J, K)`` part membership.

    """

    mirror: np.ndarray
    part: np.ndarray
    onehot: np.ndarray

    @property
    def count(self) -> int:
        """Number of parts K."""
        return self.onehot.shape[1]

    @cached_property
    def _table(self) -> np.ndarray:
        """``(2**K, J)`` the joint order of every combination of flipped parts."""
        combos = (np.arange(2**self.count)[:, None] >> np.arange(self.count)) & 1
        sided = self.part >= 0
        flipped = np.zeros((len(combos), len(self.part)), dtype=bool)
        flipped[:, sided] = combos[:, self.part[sided]].astype(bool)
        return np.where(flipped, self.mirror, np.arange(len(self.part)))

    @cached_property
    def both_orders(self) -> np.ndarray:
        """``(2, J)`` the joints as given and mirrored (indexes both labellings at once)."""
        return np.stack([np.arange(len(self.part)), self.mirror])

    def permutation(self, flips: np.ndarray) -> np.ndarray:
        """``(..., J)`` joint order relabelling the parts flagged in ``flips`` ``(..., K)``."""
        return self._table[flips.astype(np.int64) @ (1 << np.arange(self.count))]


@cache
def _mirror_parts(layout: Layout) -> _MirrorParts:
    """Split a layout into mirror parts: a sided joint belongs to its topmost sided ancestor."""
    mirror, parents = layout.mirror, layout.parents
    roots = []
    for joint in range(layout.n_joints):
        if mirror[joint] == joint:
            roots.append(-1)
            continue
        top = joint
        while parents[top] >= 0 and mirror[parents[top]] != parents[top]:
            top = parents[top]
        roots.append(min(top, int(mirror[top])))
    keys = sorted({r for r in roots if r >= 0})
    part = np.array([keys.index(r) if r >= 0 else -1 for r in roots], dtype=np.int64)
    onehot = np.zeros((layout.n_joints, len(keys)))
    onehot[part >= 0, part[part >= 0]] = 1.0
    return _MirrorParts(mirror, part, onehot)


@dataclass(frozen=True, eq=False)
class _BodyFrame:
    """Joints giving a body's up, its left and its anatomical forward (feet, nose).

    ``front`` (from the left/right labels) and ``forward`` (from where the feet and the nose
    point, whatever their labels) agree on a correctly labelled, unflipped detection; a
    front/back flip (reflected body, swapped labels) reverses ``forward`` against the true
    front, a side swap reverses ``front``.
    """

    root: int
    neck: int
    left: np.ndarray  # shoulder and hip on the left
    right: np.ndarray
    feet: np.ndarray  # (2, 2) ankle -> foot, left and right
    head: np.ndarray  # (2,) head -> nose, or empty

    @property
    def usable(self) -> bool:
        """Whether the layout names enough joints."""
        return self.neck >= 0 and len(self.left) == 2 and (len(self.feet) or len(self.head))

    def trunk(self, positions: np.ndarray) -> np.ndarray:
        """``(U, 3)`` unit root -> neck of poses (the up of a person standing)."""
        return _unit_rows(positions[:, self.neck] - positions[:, self.root])

    def front(self, positions: np.ndarray, up: np.ndarray) -> np.ndarray:
        """``(U, 3)`` unit front, cross(left, up), of poses ``(U, J, 3)`` given the up."""
        left = positions[:, self.left].sum(axis=1) - positions[:, self.right].sum(axis=1)
        return _unit_rows(_cross(left, up))

    @cached_property
    def pointers(self) -> np.ndarray:
        """``(k, 2)`` joint pairs pointing forward: ankle -> foot, head -> nose."""
        return np.concatenate([self.feet, self.head.reshape(-1, 2)]).astype(np.int64)

    def forward(self, positions: np.ndarray, up: np.ndarray) -> np.ndarray:
        """``(U, 3)`` unit anatomical forward: feet and nose directions, ⟂ up, summed."""
        steps = positions[:, self.pointers[:, 1]] - positions[:, self.pointers[:, 0]]
        steps = _unit_rows(_flat(steps, up[:, None]))  # (U, k, 3)
        return _unit_rows(np.where(np.isfinite(steps), steps, 0.0).sum(axis=1))


def _norms(vectors: np.ndarray) -> np.ndarray:
    """Euclidean norms over the last axis (without ``np.linalg.norm``'s overhead)."""
    return np.sqrt((vectors * vectors).sum(axis=-1))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of ``(..., 3)`` arrays (cheaper than ``np.cross`` on few rows)."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _unit_rows(vectors: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length; zero or NaN rows become NaN."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return vectors / np.sqrt((vectors * vectors).sum(axis=-1, keepdims=True))


def _flat(vectors: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Rows with their component along ``up`` removed."""
    return vectors - (vectors * up).sum(axis=-1, keepdims=True) * up


@cache
def _body_frame(layout: Layout) -> _BodyFrame:
    names = {name: i for i, name in enumerate(layout.joint_names)}

    def pair(a: str, b: str) -> list[int]:
        return [names[a], names[b]] if a in names and b in names else []

    sides = [pair(f"{j}Left", f"{j}Right") for j in ("Shoulder", "Hip")]
    feet = [p for p in (pair("AnkleLeft", "FootLeft"), pair("AnkleRight", "FootRight")) if p]
    return _BodyFrame(
        root=layout.parents.index(-1),
        neck=names.get("Neck", -1),
        left=np.array([s[0] for s in sides if s], dtype=np.int64),
        right=np.array([s[1] for s in sides if s], dtype=np.int64),
        feet=np.array(feet, dtype=np.int64).reshape(-1, 2),
        head=np.array(pair("Head", "Nose"), dtype=np.int64),
    )


@cache
def _side_pairs(
    layout: Layout, parts: _MirrorParts
) -> tuple[tuple[int, int] | None, np.ndarray, np.ndarray]:
    """The shoulders (left, right), and for every other part its top joints (left, right).

    Returns:
        the shoulder pair or None, ``(P, 2)`` left/right top joints and ``(P,)`` their parts.

    """
    names = layout.joint_names
    if "ShoulderLeft" not in names or "ShoulderRight" not in names:
        return None, np.empty((0, 2), dtype=np.int64), np.empty(0, dtype=np.int64)
    reference = (names.index("ShoulderLeft"), names.index("ShoulderRight"))
    pairs, part_ids = [], []
    for k in range(parts.count):
        if k == parts.part[reference[0]]:
            continue
        for joint in np.flatnonzero(parts.part == k):
            parent = layout.parents[joint]
            if "Left" in names[joint] and (parent < 0 or parts.part[parent] != k):
                pairs.append((int(joint), int(parts.mirror[joint])))
                part_ids.append(k)
    return reference, np.array(pairs, dtype=np.int64).reshape(-1, 2), np.array(part_ids)


def _misaligned(positions: np.ndarray, layout: Layout, parts: _MirrorParts) -> np.ndarray:
    """``(U, K)`` parts whose left/right pair points against the shoulders' of poses ``(U, J, 3)``.

    The shoulders' own part is never flagged; nothing is flagged where a joint is missing.
    """
    reference, pairs, part_ids = _side_pairs(layout, parts)
    flagged = np.zeros((len(positions), parts.count), dtype=bool)
    if reference is None or not len(pairs):
        return flagged
    shoulders = positions[:, reference[0]] - positions[:, reference[1]]  # (U, 3)
    sides = positions[:, pairs[:, 0]] - positions[:, pairs[:, 1]]  # (U, P, 3)
    along = np.einsum("upk,uk->up", sides, shoulders)
    scale = np.sqrt((sides * sides).sum(axis=2) * (shoulders * shoulders).sum(axis=1)[:, None])
    # Clearly reversed only (cos < -0.5): eyes 6 cm apart must not toggle on noise.
    flagged[:, part_ids] = along < -0.5 * scale
    return flagged


@cache
def _joint_weights(layout: Layout, decay: float) -> np.ndarray:
    """``(J,)`` cost weight of each joint: ``decay ** depth`` in the layout's tree.

    The root and the joints next to it place a body reliably; hands, feet and head swing, get
    occluded and are the first a front/back flip throws a metre off, so they count less.
    """
    depth = np.zeros(layout.n_joints)
    for joint in range(layout.n_joints):
        parent = layout.parents[joint]
        while parent >= 0:
            depth[joint] += 1
            parent = layout.parents[parent]
    return decay**depth


def _pair_costs(
    predicted: np.ndarray,
    detections: np.ndarray,
    weights: np.ndarray,
    parts: _MirrorParts | None,
    *,
    min_joints: int,
    margin: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean joint distance of every (track, detection) pair, sides chosen per part.

    Args:
        predicted: ``(T, J, 3)`` track poses at the detections' time.
        detections: ``(D, J, 3)``, NaN for joints left out.
        weights: ``(J,)`` joint weights of the mean.
        parts: the layout's mirror parts, or None to compare labels as given.
        min_joints: pairs sharing fewer joints cost ``inf``.
        margin: metres a part's mirror must be cheaper by (plain mean over its joints).

    Returns:
        ``(T, D)`` costs in metres and ``(T, D, K)`` flags of the parts taken mirrored.

    """
    if parts is None:
        distance = _norms(predicted[:, None] - detections[None])  # (T, D, J)
        flips = np.zeros((*distance.shape[:2], 0), dtype=bool)
    else:
        # Both labellings at once, [as given, mirrored] -> (2, T, D, J); the sums keep the
        # (D, J) @ (J, K) products per track of the separate computation (same roundings).
        labellings = detections[:, parts.both_orders].swapaxes(0, 1)[:, None]  # (2,1,D,J,3)
        both = _norms(predicted[None, :, None] - labellings)
        shared = np.isfinite(both)
        sums = np.where(shared, both, 0.0) @ parts.onehot  # (2, T, D, K)
        counts = shared @ parts.onehot
        with np.errstate(invalid="ignore", divide="ignore"):
            flips = (counts[1] > 0) & (
                sums[1] / counts[1] + margin < sums[0] / np.maximum(counts[0], 1)
            )
        # part -1 (midline) reads the appended False column
        joint_flips = np.concatenate([flips, np.zeros((*flips.shape[:2], 1), dtype=bool)], 2)
        # (np.take keeps C order: the products below then round as the separate form did)
        distance = np.where(np.take(joint_flips, parts.part, axis=2), both[1], both[0])
    shared = np.isfinite(distance)
    count = shared.sum(axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        cost = np.where(shared, distance, 0.0) @ weights / (shared @ weights)
    cost[count < min_joints] = np.inf
    return cost, flips


def _velocity_sums(times: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """``(U, J, 9)`` each sample's terms of the least-squares slope: n, t, t², p (3), t·p (3).

    Args:
        times: ``(U,)`` seconds from each track's time origin.
        positions: ``(U, J, 3)``, NaN for joints not seen.

    """
    valid = np.isfinite(positions).all(axis=2)[..., None]
    filled = np.where(valid, positions, 0.0)
    ones = valid.astype(float)
    t = times[:, None, None]
    return np.concatenate([ones, ones * t, ones * (t * t), filled, filled * t], axis=2)


def _solve_velocities(
    sums: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slopes from per-camera sums ``(U, C, J, 9)``: one intercept per camera (fixed effects).

    ``weights`` ``(J,)`` pool the joints into the body velocity (the core, as in the cost).

    Returns:
        ``(U, J, 3)`` joint velocities (0 where undetermined), ``(U, 3)`` body velocities
        (pooled over joints) and ``(U,)`` whether anything was determined.

    """
    n = np.maximum(sums[..., 0], 1.0)  # (U, C, J)
    sxx = (sums[..., 2] - sums[..., 1] ** 2 / n).sum(axis=1)  # (U, J)
    sxy = (sums[..., 6:9] - sums[..., 1:2] * sums[..., 3:6] / n[..., None]).sum(axis=1)
    determined = sxx > 1e-5
    velocities = sxy / np.where(determined, sxx, np.inf)[..., None]
    pooled = (np.where(determined, sxx, 0.0) * weights).sum(axis=1)
    body = (sxy * (determined * weights)[..., None]).sum(axis=1) / np.maximum(pooled, 1e-12)[
        :, None
    ]
    return velocities, body, determined.any(axis=1)


_REBASE_NS = 30_000_000_000
"""How often (ns) a track's running sums are rebuilt around a new time origin (precision)."""


class _Track:
    """One person's state.

    ``positions`` ``(J, 3)`` is the smoothed pose at ``time_ns``; ``velocities`` ``(J, 3)`` is
    the least-squares slope of the recent detections with one intercept per camera (so that a
    constant offset between two cameras' calibrations does not read as motion), kept as running
    sums per camera (``sums[camera]`` ``(J, 9)``, times from ``epoch_ns``) over
    ``velocity_window``; ``records`` holds the detections inside the window.
    """

    __slots__ = (
        "born_ns",
        "cameras",
        "confirmed",
        "epoch_ns",
        "facing",
        "facing_ns",
        "hits",
        "id",
        "last_hit_ns",
        "mirrored",
        "orientations",
        "positions",
        "records",
        "sums",
        "time_ns",
        "velocities",
        "velocity",
        "votes",
    )

    def __init__(self, track_id: int, positions: np.ndarray, time_ns: int) -> None:
        self.id = track_id
        self.positions = positions.copy()
        self.orientations = np.full((len(positions), 4), np.nan)
        self.velocities = np.zeros_like(positions)
        self.velocity = np.zeros(3)
        self.born_ns = self.time_ns = self.last_hit_ns = time_ns
        self.hits = 0
        self.confirmed = False
        self.cameras: dict[int, int] = {}  # camera code -> the camera's last body id for it
        self.records: deque[tuple[int, int, np.ndarray, np.ndarray]] = deque()
        self.sums = np.zeros((1, len(positions), 9))  # (cameras, J, 9)
        self.epoch_ns = time_ns
        self.votes: dict[int, tuple[int, np.ndarray]] = {}
        self.mirrored: set[int] = set()  # cameras whose last vote flips some part
        self.facing = 0.0  # log-odds that the track's sides (hence its front) are right
        self.facing_ns = time_ns

    def predict(self, time_ns: int, max_prediction: float) -> np.ndarray:
        """``(J, 3)`` pose extrapolated to ``time_ns`` with the body's mean velocity."""
        dt = min(max((time_ns - self.time_ns) * _NS, -max_prediction), max_prediction)
        return self.positions + self.velocity * dt

    def add_record(
        self, time_ns: int, camera: int, positions: np.ndarray, sums: np.ndarray, window_ns: int
    ) -> None:
        """Add a detection's terms (``sums`` ``(J, 9)``, see ``_velocity_sums``) to the fit.

        Detections older than the window leave it. Every ``_REBASE_NS`` the time origin moves
        to the newest detection and the sums are rebuilt, so that ``t²`` stays small.
        """
        if camera >= len(self.sums):
            grown = np.zeros((camera + 1, *self.sums.shape[1:]))
            grown[: len(self.sums)] = self.sums
            self.sums = grown
        self.records.append((time_ns, camera, positions, sums))
        self.sums[camera] += sums
        while self.records[0][0] < time_ns - window_ns:
            _, old_camera, _, old = self.records.popleft()
            self.sums[old_camera] -= old
        if time_ns - self.epoch_ns > _REBASE_NS:
            self.epoch_ns = time_ns
            self.sums[:] = 0.0
            rebuilt = deque()
            for t, cam, pos, _ in self.records:
                terms = _velocity_sums(np.array([(t - time_ns) * _NS]), pos[None])[0]
                self.sums[cam] += terms
                rebuilt.append((t, cam, pos, terms))
            self.records = rebuilt

    def relabel(self, permutation: np.ndarray) -> None:
        """Reorder the track's joints (swap the sides of some parts); votes are the caller's."""
        self.positions = self.positions[permutation]
        self.orientations = self.orientations[permutation]
        self.velocities = self.velocities[permutation]
        self.records = deque(
            (t, cam, pos[permutation], terms[permutation]) for t, cam, pos, terms in self.records
        )
        self.sums = self.sums[:, permutation]


class Tracker:
    """Gives every camera detection a persistent track id (see the module docstring).

    Attributes:
        params: the parameters it was built with.
        drops: reason -> count of input left out (uncalibrated camera, late frame, ...).
        correction: the calibration being applied (``set_calibration`` replaces it).

    """

    def __init__(
        self, params: TrackerParams | None = None, calibration: Calibration | None = None
    ) -> None:
        self.params = params or TrackerParams()
        self.drops: Counter[str] = Counter()
        self.correction = CameraCorrection(calibration, self.drops)
        self._tracks: list[_Track] = []
        self._next_id = 0
        self._buffer: list[tuple[int, int, str, SkeletonGroup]] = []
        self._sequence = itertools.count()
        self._camera_codes: dict[str, int] = {}
        self._newest_ns: int | None = None
        self._released_ns: int | None = None
        self._up: np.ndarray | None = None

    # ----------------------------------------------------------------------------- calibration
    def set_calibration(self, calibration: Calibration) -> None:
        """Use a new calibration from the next frame on (tracks are kept)."""
        self.correction.set_calibration(calibration)

    def set_camera(self, name: str, camera: CameraCalibration) -> None:
        """Replace one camera's calibration from the next frame on."""
        self.correction.set_camera(name, camera)

    @property
    def uncalibrated(self) -> set[str]:
        """Cameras whose frames were dropped for want of a calibration."""
        return self.correction.uncalibrated

    # ---------------------------------------------------------------------------------- state
    @property
    def track_ids(self) -> list[int]:
        """Ids of the confirmed tracks."""
        return [track.id for track in self._tracks if track.confirmed]

    @property
    def pending(self) -> int:
        """Frames waiting in the out-of-order buffer."""
        return len(self._buffer)

    # ----------------------------------------------------------------------------------- flow
    def update(self, group: SkeletonGroup) -> SkeletonGroup:
        """Take one camera frame; return the detections released by it, with track ids.

        The returned group holds every detection of confirmed tracks from the frames released
        by this call (zero or more frames, in reference-time order): world frame, header stamp
        = the last released frame's corrected stamp.
        """
        corrected = self.correction.apply(group)
        if corrected is None:
            return self._output([])
        if self._released_ns is not None and corrected.stamp_ns < self._released_ns:
            self.drops["late frame"] += 1
            return self._output([])
        camera = self.correction.camera_name(group) or group.camera
        heapq.heappush(self._buffer, (corrected.stamp_ns, next(self._sequence), camera, corrected))
        if self._newest_ns is None or corrected.stamp_ns > self._newest_ns:
            self._newest_ns = corrected.stamp_ns
        return self._release(self._newest_ns - round(self.params.max_delay * 1e9))

    def flush(self) -> SkeletonGroup:
        """Process every buffered frame now (end of a recording)."""
        return self._release(None)

    def _release(self, horizon_ns: int | None) -> SkeletonGroup:
        skeletons: list[Skeleton] = []
        while self._buffer and (horizon_ns is None or self._buffer[0][0] <= horizon_ns):
            stamp_ns, _, camera, frame = heapq.heappop(self._buffer)
            self._released_ns = stamp_ns
            skeletons.extend(self._process(frame, camera))
        return self._output(skeletons)

    def _output(self, skeletons: list[Skeleton]) -> SkeletonGroup:
        stamp = self._released_ns if self._released_ns is not None else 0
        return SkeletonGroup(stamp, self.correction.world_frame, skeletons)

    # ---------------------------------------------------------------------------- association
    def _process(self, frame: SkeletonGroup, camera: str) -> list[Skeleton]:
        """Associate one world-frame camera frame with the tracks; return confirmed outputs."""
        code = self._camera_codes.setdefault(camera, len(self._camera_codes))
        self._expire(frame.stamp_ns)
        detections = self._valid_detections(frame.skeletons)
        if not detections:
            return []
        params = self.params
        parts = _mirror_parts(detections[0].layout)
        stamp = detections[0].src_time_ns
        positions = np.array([d.positions for d in detections])  # (D, J, 3)
        usable = np.array([d.marker_present for d in detections])
        if params.min_confidence > 0:
            usable &= ~(np.array([d.confidences for d in detections]) < params.min_confidence)
        positions = np.where(usable[..., None], positions, np.nan)

        no_flip = np.zeros(parts.count, dtype=bool)
        assigned: dict[int, tuple[_Track, np.ndarray]] = {}
        free = list(range(len(detections)))
        recent_ns = stamp - round(params.recent_window * 1e9)
        for tracks in self._cascade(recent_ns):
            if tracks and free:
                for det, track, flips in self._match(
                    tracks, detections, positions, free, stamp=stamp, camera=code
                ):
                    assigned[det] = (track, flips)
                free = [d for d in free if d not in assigned]

        pairs: list[tuple[int, _Track, np.ndarray]] = []
        for det in range(len(detections)):
            if det in assigned:
                pairs.append((det, *assigned[det]))
            elif np.isfinite(positions[det]).all(axis=1).sum() >= params.min_joints:
                pairs.append((det, self._new_track(positions[det], stamp), no_flip))
            else:
                self.drops["too few joints"] += 1
        if not pairs:
            return []
        flips = np.array([f for _, _, f in pairs])  # (U, K)
        rows = np.array([det for det, _, _ in pairs])
        canonical = positions[rows[:, None], parts.permutation(flips)]  # (U, J, 3)
        if params.mirror_check and params.facing_check:
            # Which hip, eye or ear is left is geometry once the shoulders are labelled.
            aligned = _misaligned(canonical, detections[0].layout, parts)
            if aligned.any():
                flips = flips ^ aligned
                canonical = positions[rows[:, None], parts.permutation(flips)]
        tracks = [track for _, track, _ in pairs]
        chosen = [detections[det] for det in rows]
        position = self.correction.cameras.get(camera)
        flips = flips ^ self._hit(
            tracks,
            canonical,
            chosen,
            parts,
            stamp,
            code,
            flips,
            None if position is None else np.asarray(position.translation, dtype=float),
        )
        orders = parts.permutation(flips)
        return [
            self._labelled(detection, track, order)
            for detection, track, order in zip(chosen, tracks, orders, strict=True)
            if track.confirmed
        ]

    def _cascade(self, recent_ns: int) -> tuple[list[_Track], list[_Track], list[_Track]]:
        """Tracks in matching order: confirmed and seen recently, confirmed, tentative.

        Like DeepSORT's matching cascade: a track that has just lost its person (who left,
        or whom every camera lost) must not take a detection that a live track explains.
        """
        live = [t for t in self._tracks if t.confirmed and t.last_hit_ns >= recent_ns]
        stale = [t for t in self._tracks if t.confirmed and t.last_hit_ns < recent_ns]
        return live, stale, [t for t in self._tracks if not t.confirmed]

    def _valid_detections(self, skeletons: list[Skeleton]) -> list[Skeleton]:
        """Skeletons with a finite joint and the layout of the first one (and of the tracks)."""
        valid: list[Skeleton] = []
        for skeleton in skeletons:
            if valid and skeleton.layout is not valid[0].layout:
                self.drops["layout differs within a frame"] += 1
            elif not (skeleton.marker_present & np.isfinite(skeleton.positions).all(1)).any():
                self.drops["no finite joint"] += 1
            else:
                valid.append(skeleton)
        if valid and self._tracks and valid[0].layout.n_joints != len(self._tracks[0].positions):
            self.drops["layout differs from the tracks"] += len(valid)
            return []
        return valid

    def _match(
        self,
        tracks: list[_Track],
        detections: list[Skeleton],
        positions: np.ndarray,
        free: list[int],
        *,
        stamp: int,
        camera: int,
    ) -> list[tuple[int, _Track, np.ndarray]]:
        """Optimal assignment of ``free`` detections to ``tracks``: (detection, track, flips)."""
        params = self.params
        parts = _mirror_parts(detections[0].layout)
        predicted = np.array([t.predict(stamp, params.max_prediction) for t in tracks])
        cost, flips = _pair_costs(
            predicted,
            positions[free],
            _joint_weights(detections[0].layout, params.joint_weight_decay),
            parts if params.mirror_check else None,
            min_joints=params.min_joints,
            margin=params.mirror_margin,
        )
        if not params.mirror_check:
            flips = np.zeros((*cost.shape, parts.count), dtype=bool)
        if params.velocity_weight > 0 or params.orientation_weight > 0:
            cost = cost + self._motion_costs(tracks, [detections[d] for d in free], parts, flips)
        if params.body_id_bonus:
            cost = cost + params.body_id_bonus * self._body_id_terms(
                tracks, detections, free, camera
            )
        unseen = np.array([(stamp - t.last_hit_ns) * _NS for t in tracks])
        gate = params.gate_distance + params.gate_growth * np.clip(unseen, 0.0, None)
        feasible = np.isfinite(cost) & (cost <= gate[:, None])
        if not feasible.any():
            return []
        rows, cols = linear_sum_assignment(np.where(feasible, cost, _INFEASIBLE))
        return [
            (free[c], tracks[r], flips[r, c])
            for r, c in zip(rows, cols, strict=True)
            if feasible[r, c]
        ]

    @staticmethod
    def _body_id_terms(
        tracks: list[_Track], detections: list[Skeleton], free: list[int], camera: int
    ) -> np.ndarray:
        """``(T, D)`` body-id evidence: -1 agrees, +1 contradicts, 0 says nothing.

        -1 where the camera keeps the body id it gave the track last time; +1 for the track's
        other candidates when that id is in the frame (the camera still follows the track's
        body as another detection).
        """
        ids = np.array([detections[d].id for d in free])
        frame_ids = {detection.id for detection in detections if detection.id >= 0}
        known = np.array([t.cameras.get(camera, -1) for t in tracks])
        same = (known[:, None] == ids) & (ids >= 0)
        elsewhere = np.array([k >= 0 and k in frame_ids for k in known])[:, None] & ~same
        return elsewhere.astype(float) - same

    def _motion_costs(
        self,
        tracks: list[_Track],
        detections: list[Skeleton],
        parts: _MirrorParts,
        flips: np.ndarray,
    ) -> np.ndarray:
        """``(T, D)`` weighted velocity (m/s) and orientation (rad) differences, 0 if unknown."""
        params = self.params
        order = parts.permutation(flips)  # (T, D, J): each pair's relabelling
        pick = np.arange(len(detections))[None, :, None]
        cost = np.zeros(flips.shape[:2])
        if params.velocity_weight > 0:
            det_v = np.array([d.velocities for d in detections])[pick, order]  # (T, D, J, 3)
            track_v = np.array([t.velocities for t in tracks])[:, None]
            cost += params.velocity_weight * _nan_mean(np.linalg.norm(det_v - track_v, axis=3))
        if params.orientation_weight > 0:
            det_q = np.array([d.orientations for d in detections])[pick, order]
            track_q = np.array([t.orientations for t in tracks])[:, None]
            dot = np.abs((det_q * track_q).sum(axis=3))
            angle = 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))
            cost += params.orientation_weight * _nan_mean(angle)
        return cost

    # -------------------------------------------------------------------------------- updates
    def _new_track(self, positions: np.ndarray, time_ns: int) -> _Track:
        track = _Track(self._next_id, positions, time_ns)
        self._next_id += 1
        self._tracks.append(track)
        return track

    def _hit(  # noqa: PLR0917 - one frame's matched pairs, all positional for brevity
        self,
        tracks: list[_Track],
        canonical: np.ndarray,
        detections: list[Skeleton],
        parts: _MirrorParts,
        time_ns: int,
        camera: int,
        flips: np.ndarray,
        camera_position: np.ndarray | None = None,
    ) -> np.ndarray:
        """Fold one frame's detections (already in their tracks' labelling) into the tracks.

        Args:
            tracks: the U tracks hit (distinct).
            canonical: ``(U, J, 3)`` their detections, relabelled to the tracks' sides.
            detections: the U detections as received (ids, orientations).
            parts: the layout's mirror parts.
            time_ns: the frame's corrected stamp.
            camera: the frame's camera code.
            flips: ``(U, K)`` parts relabelled per detection.
            camera_position: ``(3,)`` the camera's position in the world, None if unknown.

        Returns:
            ``(U, K)`` the parts whose sides a track itself swapped (mirror vote), which the
            caller swaps in that detection's output too.

        """
        params = self.params
        previous = np.array([t.time_ns for t in tracks])
        now = np.maximum(previous, time_ns)
        dt = np.clip((now - previous) * _NS, -params.max_prediction, params.max_prediction)
        positions = np.array([t.positions for t in tracks])
        predicted = positions + np.array([t.velocity for t in tracks])[:, None] * dt[:, None, None]
        alpha = np.array([params.position_smoothing if t.hits else 1.0 for t in tracks])
        measured = np.isfinite(canonical).all(axis=2)[..., None]
        updated = np.where(
            measured, predicted + alpha[:, None, None] * (canonical - predicted), predicted
        )
        updated = np.where(np.isfinite(updated), updated, canonical)
        epochs = np.array([t.epoch_ns for t in tracks])
        terms = _velocity_sums((time_ns - epochs) * _NS, canonical)
        window_ns = round(params.velocity_window * 1e9)
        for u, track in enumerate(tracks):
            track.positions = updated[u]
            track.time_ns = int(now[u])
            track.last_hit_ns = max(track.last_hit_ns, time_ns)
            track.hits += 1
            track.cameras[camera] = detections[u].id
            track.add_record(time_ns, camera, canonical[u], terms[u], window_ns)
        if params.orientation_weight > 0:
            for track, detection, order in zip(
                tracks, detections, parts.permutation(flips), strict=True
            ):
                if np.isfinite(detection.orientations).any():
                    track.orientations = detection.orientations[order]
        cameras = max(len(t.sums) for t in tracks)
        sums = np.zeros((len(tracks), cameras, *tracks[0].sums.shape[1:]))
        for u, track in enumerate(tracks):
            sums[u, : len(track.sums)] = track.sums
        weights = _joint_weights(detections[0].layout, params.joint_weight_decay)
        velocities, body, determined = _solve_velocities(sums, weights)

        for u, track in enumerate(tracks):
            if determined[u]:
                track.velocities = velocities[u]
                track.velocity = body[u]
        swaps = np.zeros_like(flips)
        frame = _body_frame(detections[0].layout)
        facing = params.mirror_check and params.facing_check and bool(frame.usable)
        if facing:
            turned = self._facing(
                tracks,
                canonical,
                frame,
                mirror=parts.mirror,
                time_ns=time_ns,
                camera_position=camera_position,
            )
            swaps[turned] = True
        for u, track in enumerate(tracks):
            if not track.confirmed and track.hits >= params.min_hits:
                self._confirm(track, detections[u].layout, time_ns)
            if params.mirror_check and params.mirror_vote and track.confirmed and not facing:
                swaps[u] ^= self._vote(track, parts, camera, time_ns, flips[u] ^ swaps[u])
        return swaps

    def _world_up(self, trunks: np.ndarray) -> np.ndarray:
        """``(3,)`` the world's up, a running mean of people's trunks (root -> neck).

        The world frame may be a camera's (y down) or z-up; people stand most of the time,
        and one bending person must not tilt the front the facing check compares with.
        """
        trunks = trunks[np.isfinite(trunks).all(axis=1)]
        if len(trunks):
            mean = trunks.mean(axis=0)
            self._up = mean if self._up is None else self._up + 0.01 * (mean - self._up)
            self._up = self._up / np.linalg.norm(self._up)
        return self._up if self._up is not None else np.full(3, np.nan)

    def _facing(
        self,
        tracks: list[_Track],
        canonical: np.ndarray,
        frame: _BodyFrame,
        *,
        mirror: np.ndarray,
        time_ns: int,
        camera_position: np.ndarray | None,
    ) -> np.ndarray:
        """Weigh one frame's evidence on each track's facing; relabel tracks found reversed.

        For a detection (in its track's labelling) with anatomical forward ``a`` and a track
        front ``f``: if the track is right, the detection is flipped iff ``a·f < 0``; if the
        track is mirrored, the opposite, and its front is ``-f``. Each hypothesis' likelihood
        uses the flip prior for the view the camera would have (back: cos(f, to camera) < -0.5).

        Returns:
            ``(U,)`` which tracks were relabelled (all their parts swapped).

        """
        params = self.params
        positions = np.array([t.positions for t in tracks])
        up = np.broadcast_to(self._world_up(frame.trunk(positions)), positions[:, 0].shape)
        front = frame.front(positions, up)
        forward = frame.forward(canonical, up)
        flipped = (forward * front).sum(axis=1) < 0
        evidence = np.zeros(len(tracks))
        if camera_position is not None:
            to_camera = _unit_rows(_flat(camera_position - positions[:, frame.root], up))
            cosine = (front * to_camera).sum(axis=1)
            prior_right = np.where(cosine < -0.5, params.flip_prior_back, params.flip_prior)
            prior_wrong = np.where(-cosine < -0.5, params.flip_prior_back, params.flip_prior)
            likely_right = np.where(flipped, prior_right, 1.0 - prior_right)
            likely_wrong = np.where(flipped, 1.0 - prior_wrong, prior_wrong)
            evidence += np.log(likely_right / likely_wrong)
        else:  # no camera pose: a flipped-looking detection is simply evidence against
            evidence += np.where(flipped, -1.0, 1.0) * np.log(
                (1.0 - params.flip_prior) / params.flip_prior
            )
        velocity = np.array([t.velocity for t in tracks])
        walking = _flat(velocity, up)
        speed = np.linalg.norm(walking, axis=1)
        along = (walking * front).sum(axis=1) / np.maximum(speed, 1e-9)
        evidence += np.where(speed > params.walking_speed, np.sign(along), 0.0) * (
            params.walking_evidence
        )
        evidence = np.where(np.isfinite(evidence), evidence, 0.0)
        turned = np.zeros(len(tracks), dtype=bool)
        for u, track in enumerate(tracks):
            fade = np.exp(-max(time_ns - track.facing_ns, 0) * _NS / params.facing_memory)
            track.facing = track.facing * fade + evidence[u]
            track.facing_ns = time_ns
            if track.facing < -params.facing_threshold:
                track.relabel(mirror)
                track.votes = {cam: (t, ~vote) for cam, (t, vote) in track.votes.items()}
                track.mirrored = {cam for cam, (_, vote) in track.votes.items() if vote.any()}
                track.facing = -track.facing
                turned[u] = True
        return turned

    def _vote(
        self, track: _Track, parts: _MirrorParts, camera: int, time_ns: int, flips: np.ndarray
    ) -> np.ndarray:
        """Swap a track's sides of the parts that most cameras seeing it now call mirrored.

        The fallback for layouts without the joints the facing check needs.
        """
        track.votes[camera] = (time_ns, flips)
        if not flips.any():
            track.mirrored.discard(camera)
            if not track.mirrored:  # nobody calls the sides mirrored: nothing to count
                return np.zeros_like(flips)
        else:
            track.mirrored.add(camera)
        recent = time_ns - round(self.params.velocity_window * 1e9)
        votes = [vote for t, vote in track.votes.values() if t >= recent]
        if len(votes) < 2:
            return np.zeros_like(flips)
        swap = 2 * np.sum(votes, axis=0) > len(votes)
        if swap.any():
            track.relabel(parts.permutation(swap))
            track.votes = {cam: (t, vote ^ swap) for cam, (t, vote) in track.votes.items()}
            track.mirrored = {cam for cam, (_, vote) in track.votes.items() if vote.any()}
        return swap

    def _confirm(self, track: _Track, layout: Layout, time_ns: int) -> None:
        """Confirm a tentative track seen enough, unless it duplicates a confirmed one."""
        params = self.params
        cameras = min(params.min_cameras, max(len(self.correction.cameras), 1))
        old_enough = (time_ns - track.born_ns) * _NS >= params.single_camera_confirm
        if len(track.cameras) < cameras and not old_enough:
            return
        confirmed = [t for t in self._tracks if t.confirmed]
        if confirmed:
            predicted = np.array([t.predict(time_ns, params.max_prediction) for t in confirmed])
            weights = _joint_weights(layout, params.joint_weight_decay)
            distance, _ = _pair_costs(
                predicted,
                track.positions[None],
                weights,
                None,
                min_joints=params.min_joints,
                margin=0.0,
            )
            if (distance < params.duplicate_distance).any():
                self._tracks.remove(track)
                self.drops["duplicate of a confirmed track"] += 1
                return
        track.confirmed = True

    def _expire(self, now_ns: int) -> None:
        params = self.params
        self._tracks = [
            track
            for track in self._tracks
            if (now_ns - track.last_hit_ns) * _NS
            <= (params.track_timeout if track.confirmed else params.tentative_timeout)
        ]

    def _labelled(self, detection: Skeleton, track: _Track, order: np.ndarray) -> Skeleton:
        """The output skeleton of one detection: track id, sides fixed, velocities filled.

        The detection is the tracker's own copy (made by the correction), so it is changed in
        place. Link ids are child joint ids, so links take the joints' order.
        """
        out = detection
        if (order != np.arange(len(order))).any():
            out.markers = out.markers[order]
            out.marker_present = out.marker_present[order]
            out.links = out.links[order]
            out.link_present = out.link_present[order]
        out.id = track.id
        missing = out.marker_present & ~np.isfinite(out.velocities).all(axis=1)
        out.velocities[missing] = track.velocities[missing]
        return out


def _nan_mean(values: np.ndarray) -> np.ndarray:
    """Mean over the last axis ignoring NaN; 0 where all are NaN."""
    finite = np.isfinite(values)
    return np.where(finite, values, 0.0).sum(axis=-1) / np.maximum(finite.sum(axis=-1), 1)
