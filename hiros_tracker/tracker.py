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
import math
from collections import Counter, deque
from dataclasses import dataclass
from functools import cache, cached_property

import numpy as np
from scipy.optimize import linear_sum_assignment

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.layouts import AZURE_KINECT, Layout
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_tracker import kernels
from hiros_tracker.correction import CameraCorrection

__all__ = ["Tracker", "TrackerParams"]

_NS = 1e-9
_INFEASIBLE = 1e9
"""Cost given to gated-out pairs so that the solver still sees a full matrix."""
_NO_CAMERA = np.zeros(3)
"""Placeholder camera position for the facing kernel when the camera's pose is unknown."""


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

    The front (from the left/right labels) and the forward (from where the feet and the nose
    point, whatever their labels; both computed in ``kernels.facing_evidence``) agree on a
    correctly labelled, unflipped detection; a front/back flip (reflected body, swapped
    labels) reverses the forward against the true front, a side swap reverses the front.
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

    @cached_property
    def pointers(self) -> np.ndarray:
        """``(k, 2)`` joint pairs pointing forward: ankle -> foot, head -> nose."""
        return np.concatenate([self.feet, self.head.reshape(-1, 2)]).astype(np.int64)


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


@cache
def _side_arrays(layout: Layout, parts: _MirrorParts) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``_side_pairs`` as arrays for the kernels: ``(2,)`` shoulders (or empty), pairs, parts."""
    reference, pairs, part_ids = _side_pairs(layout, parts)
    shoulders = np.array(reference if reference is not None else (), dtype=np.int64)
    return shoulders, pairs.astype(np.int64), part_ids.astype(np.int64).reshape(-1)


@dataclass(frozen=True, eq=False)
class _LayoutInfo:
    """What the tracker derives from a layout, looked up once per frame."""

    layout: Layout
    parts: _MirrorParts
    weights: np.ndarray  # (J,) cost weights (_joint_weights)
    frame: _BodyFrame
    sides: tuple[np.ndarray, np.ndarray, np.ndarray]  # _side_arrays


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
        warm_up()
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
        self._info: _LayoutInfo | None = None
        self._camera_positions: dict[str, tuple[CameraCalibration, np.ndarray]] = {}

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
        detections, positions, kept = self._valid_detections(frame.skeletons)
        if not detections:
            return []
        params = self.params
        info = self._layout_info(detections[0].layout)
        parts = info.parts
        stamp = detections[0].src_time_ns

        no_flip = np.zeros(parts.count, dtype=bool)
        assigned: dict[int, tuple[_Track, np.ndarray]] = {}
        free = list(range(len(detections)))
        recent_ns = stamp - round(params.recent_window * 1e9)
        for tracks in self._cascade(recent_ns):
            if tracks and free:
                for det, track, flips in self._match(
                    tracks, detections, positions, free, stamp=stamp, camera=code, info=info
                ):
                    assigned[det] = (track, flips)
                free = [d for d in free if d not in assigned]

        pairs: list[tuple[int, _Track, np.ndarray]] = []
        for det in range(len(detections)):
            if det in assigned:
                pairs.append((det, *assigned[det]))
            elif kept[det] >= params.min_joints:
                pairs.append((det, self._new_track(positions[det], stamp), no_flip))
            else:
                self.drops["too few joints"] += 1
        if not pairs:
            return []
        # Detections in their tracks' labelling; which hip, eye or ear is left is then
        # geometry once the shoulders are labelled (with the facing check).
        shoulders, side_pairs, side_parts = info.sides
        canonical, flips = kernels.canonical_poses(
            positions,
            np.array([det for det, _, _ in pairs]),
            np.array([f for _, _, f in pairs]),
            parts.part,
            parts.mirror,
            params.mirror_check and params.facing_check,
            shoulders,
            side_pairs,
            side_parts,
        )
        tracks = [track for _, track, _ in pairs]
        chosen = [detections[det] for det, _, _ in pairs]
        flips = flips ^ self._hit(
            tracks, canonical, chosen, info, stamp, code, flips, self._camera_position(camera)
        )
        return [
            self._labelled(detection, track, flips[u], parts)
            for u, (detection, track) in enumerate(zip(chosen, tracks, strict=True))
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

    def _valid_detections(
        self, skeletons: list[Skeleton]
    ) -> tuple[list[Skeleton], np.ndarray, np.ndarray]:
        """Skeletons with a finite joint and the layout of the first one (and of the tracks).

        Returns them, their ``(D, J, 3)`` positions (NaN where absent or below
        ``min_confidence``) and ``(D,)`` how many finite joints each keeps.
        """
        empty = ([], np.empty((0, 0, 3)), np.empty(0, dtype=np.int64))
        if not skeletons:
            return empty
        layout = skeletons[0].layout
        if any(skeleton.layout is not layout for skeleton in skeletons):
            valid: list[Skeleton] = []
            for skeleton in skeletons:
                if valid and skeleton.layout is not valid[0].layout:
                    self.drops["layout differs within a frame"] += 1
                elif not (skeleton.marker_present & np.isfinite(skeleton.positions).all(1)).any():
                    self.drops["no finite joint"] += 1
                else:
                    valid.append(skeleton)
            if not valid:
                return empty
            skeletons = valid
        positions, usable, kept = kernels.masked_positions(
            np.array([s.markers for s in skeletons]),
            np.array([s.marker_present for s in skeletons]),
            self.params.min_confidence,
        )
        if not usable.all():
            self.drops["no finite joint"] += int((~usable).sum())
            skeletons = [s for s, ok in zip(skeletons, usable.tolist(), strict=True) if ok]
            positions, kept = positions[usable], kept[usable]
        if (
            skeletons
            and self._tracks
            and skeletons[0].layout.n_joints != len(self._tracks[0].positions)
        ):
            self.drops["layout differs from the tracks"] += len(skeletons)
            return empty
        return skeletons, positions, kept

    def _camera_position(self, camera: str) -> np.ndarray | None:
        """``(3,)`` the camera's position in the world (from its current calibration) or None."""
        calibration = self.correction.cameras.get(camera)
        if calibration is None:
            return None
        cached = self._camera_positions.get(camera)
        if cached is None or cached[0] is not calibration:
            position = np.asarray(calibration.translation, dtype=float)
            cached = self._camera_positions[camera] = (calibration, position)
        return cached[1]

    def _layout_info(self, layout: Layout) -> _LayoutInfo:
        """The layout's mirror parts, joint weights, body frame and side pairs (kept per layout)."""
        if self._info is None or self._info.layout is not layout:
            parts = _mirror_parts(layout)
            self._info = _LayoutInfo(
                layout,
                parts,
                _joint_weights(layout, self.params.joint_weight_decay),
                _body_frame(layout),
                _side_arrays(layout, parts),
            )
        return self._info

    def _match(
        self,
        tracks: list[_Track],
        detections: list[Skeleton],
        positions: np.ndarray,
        free: list[int],
        *,
        stamp: int,
        camera: int,
        info: _LayoutInfo,
    ) -> list[tuple[int, _Track, np.ndarray]]:
        """Optimal assignment of ``free`` detections to ``tracks``: (detection, track, flips)."""
        params = self.params
        parts = info.parts
        cost, flips = kernels.match_costs(
            *_motion_state(tracks),
            stamp,
            params.max_prediction,
            positions if len(free) == len(positions) else positions[free],
            info.weights,
            parts.part,
            parts.mirror,
            parts.count,
            params.mirror_check,
            params.min_joints,
            params.mirror_margin,
        )
        if params.velocity_weight > 0 or params.orientation_weight > 0:
            cost = cost + self._motion_costs(tracks, [detections[d] for d in free], parts, flips)
        if params.body_id_bonus:
            cost = cost + params.body_id_bonus * np.array(
                self._body_id_terms(tracks, detections, free, camera)
            )
        gate = np.array(
            [
                params.gate_distance + params.gate_growth * max((stamp - t.last_hit_ns) * _NS, 0.0)
                for t in tracks
            ]
        )
        feasible = np.isfinite(cost) & (cost <= gate[:, None])
        if not feasible.any():
            return []
        rows, cols = linear_sum_assignment(np.where(feasible, cost, _INFEASIBLE))
        return [
            (free[c], tracks[r], flips[r, c])
            for r, c in zip(rows.tolist(), cols.tolist(), strict=True)
            if feasible[r, c]
        ]

    @staticmethod
    def _body_id_terms(
        tracks: list[_Track], detections: list[Skeleton], free: list[int], camera: int
    ) -> list[list[float]]:
        """``(T, D)`` body-id evidence: -1 agrees, +1 contradicts, 0 says nothing.

        -1 where the camera keeps the body id it gave the track last time; +1 for the track's
        other candidates when that id is in the frame (the camera still follows the track's
        body as another detection). A few dozen pairs: plain Python beats numpy here.
        """
        ids = [detections[d].id for d in free]
        frame_ids = {detection.id for detection in detections if detection.id >= 0}
        terms = []
        for track in tracks:
            known = track.cameras.get(camera, -1)
            elsewhere = 1.0 if known >= 0 and known in frame_ids else 0.0
            terms.append([-1.0 if known == i and i >= 0 else elsewhere for i in ids])
        return terms

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

    def _hit(  # noqa: PLR0912, PLR0917 - one frame's matched pairs, all positional for brevity
        self,
        tracks: list[_Track],
        canonical: np.ndarray,
        detections: list[Skeleton],
        info: _LayoutInfo,
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
            info: the layout's mirror parts, weights and body frame.
            time_ns: the frame's corrected stamp.
            camera: the frame's camera code.
            flips: ``(U, K)`` parts relabelled per detection.
            camera_position: ``(3,)`` the camera's position in the world, None if unknown.

        Returns:
            ``(U, K)`` the parts whose sides a track itself swapped (mirror vote), which the
            caller swaps in that detection's output too.

        """
        params = self.params
        parts = info.parts
        updated, terms = kernels.hit_update(
            np.array([t.positions for t in tracks]),
            np.array([t.velocity for t in tracks]),
            np.array([t.time_ns for t in tracks], dtype=np.int64),
            np.array([t.epoch_ns for t in tracks], dtype=np.int64),
            np.array([params.position_smoothing if t.hits else 1.0 for t in tracks]),
            canonical,
            time_ns,
            params.max_prediction,
        )
        window_ns = round(params.velocity_window * 1e9)
        for u, track in enumerate(tracks):
            track.positions = updated[u]
            track.time_ns = max(track.time_ns, time_ns)
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
        if all(len(t.sums) == cameras for t in tracks):
            sums = np.array([t.sums for t in tracks])
        else:
            sums = np.zeros((len(tracks), cameras, *tracks[0].sums.shape[1:]))
            for u, track in enumerate(tracks):
                sums[u, : len(track.sums)] = track.sums
        velocities, body, determined = kernels.solve_velocities(sums, info.weights)
        for u, track in enumerate(tracks):
            if determined[u]:
                track.velocities = velocities[u]
                track.velocity = body[u]
        swaps = np.zeros_like(flips)
        frame = info.frame
        facing = params.mirror_check and params.facing_check and bool(frame.usable)
        if facing:
            turned = self._facing(
                tracks,
                updated,
                canonical,
                frame,
                mirror=parts.mirror,
                time_ns=time_ns,
                camera_position=camera_position,
            )
            swaps[turned] = True
        for u, track in enumerate(tracks):
            if not track.confirmed and track.hits >= params.min_hits:
                self._confirm(track, info, time_ns)
            if params.mirror_check and params.mirror_vote and track.confirmed and not facing:
                swaps[u] ^= self._vote(track, parts, camera, time_ns, flips[u] ^ swaps[u])
        return swaps

    def _world_up(self, positions: np.ndarray, frame: _BodyFrame) -> np.ndarray:
        """``(3,)`` the world's up, a running mean of people's trunks (root -> neck).

        The world frame may be a camera's (y down) or z-up; people stand most of the time,
        and one bending person must not tilt the front the facing check compares with.
        """
        mean, count = kernels.trunk_mean(positions, frame.root, frame.neck)
        if count:
            self._up = mean if self._up is None else self._up + 0.01 * (mean - self._up)
            self._up = self._up / np.linalg.norm(self._up)
        return self._up if self._up is not None else np.full(3, np.nan)

    def _facing(
        self,
        tracks: list[_Track],
        positions: np.ndarray,
        canonical: np.ndarray,
        frame: _BodyFrame,
        *,
        mirror: np.ndarray,
        time_ns: int,
        camera_position: np.ndarray | None,
    ) -> np.ndarray:
        """Weigh one frame's evidence on each track's facing; relabel tracks found reversed.

        For a detection (in its track's labelling) with anatomical forward ``a`` and a track
        front ``f`` (``positions`` ``(U, J, 3)``: the tracks' poses): if the track is right,
        the detection is flipped iff ``a·f < 0``; if the track is mirrored, the opposite, and
        its front is ``-f``. Each hypothesis' likelihood uses the flip prior for the view the
        camera would have (back: cos(f, to camera) < -0.5); walking forward adds evidence
        (``kernels.facing_evidence`` computes it).

        Returns:
            ``(U,)`` which tracks were relabelled (all their parts swapped).

        """
        params = self.params
        up = self._world_up(positions, frame)
        evidence = kernels.facing_evidence(
            positions,
            canonical,
            np.array([t.velocity for t in tracks]),
            up,
            _NO_CAMERA if camera_position is None else camera_position,
            camera_position is not None,
            frame.root,
            frame.left,
            frame.right,
            frame.pointers,
            params.flip_prior,
            params.flip_prior_back,
            params.walking_speed,
            params.walking_evidence,
        ).tolist()
        turned = np.zeros(len(tracks), dtype=bool)
        for u, track in enumerate(tracks):
            fade = math.exp(-max(time_ns - track.facing_ns, 0) * _NS / params.facing_memory)
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

    def _confirm(self, track: _Track, info: _LayoutInfo, time_ns: int) -> None:
        """Confirm a tentative track seen enough, unless it duplicates a confirmed one."""
        params = self.params
        cameras = min(params.min_cameras, max(len(self.correction.cameras), 1))
        old_enough = (time_ns - track.born_ns) * _NS >= params.single_camera_confirm
        if len(track.cameras) < cameras and not old_enough:
            return
        confirmed = [t for t in self._tracks if t.confirmed]
        if confirmed:
            distance, _ = kernels.match_costs(
                *_motion_state(confirmed),
                time_ns,
                params.max_prediction,
                track.positions[None],
                info.weights,
                info.parts.part,
                info.parts.mirror,
                info.parts.count,
                False,
                params.min_joints,
                0.0,
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

    @staticmethod
    def _labelled(
        detection: Skeleton, track: _Track, flips: np.ndarray, parts: _MirrorParts
    ) -> Skeleton:
        """The output skeleton of one detection: track id, sides fixed, velocities filled.

        The detection is the tracker's own copy (made by the correction), so it is changed in
        place: the parts in ``flips`` relabelled (links too: link ids are child joint ids),
        present joints without a velocity given the track's.
        """
        kernels.label_rows(
            detection.markers,
            detection.marker_present,
            detection.links,
            detection.link_present,
            flips,
            parts.part,
            parts.mirror,
            track.velocities,
        )
        detection.id = track.id
        return detection


def _motion_state(tracks: list[_Track]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses, body velocities and times (ns): what ``kernels.match_costs`` predicts from."""
    return (
        np.array([t.positions for t in tracks]),
        np.array([t.velocity for t in tracks]),
        np.array([t.time_ns for t in tracks], dtype=np.int64),
    )


def _nan_mean(values: np.ndarray) -> np.ndarray:
    """Mean over the last axis ignoring NaN; 0 where all are NaN."""
    finite = np.isfinite(values)
    return np.where(finite, values, 0.0).sum(axis=-1) / np.maximum(finite.sum(axis=-1), 1)


_WARM = False


def warm_up() -> None:
    """Compile the kernels (or load them from numba's disk cache) once per process.

    The first ``Tracker`` of a process calls it, so that a live node pays the cost (about
    0.3 s from the cache, 10-20 s on the very first run after an install or a kernel change)
    before its first frame rather than on it: a burst of frames arriving during that first
    frame would otherwise overflow the subscription queue. A throwaway tracker follows one
    standing person seen by a calibrated camera through every code path a frame takes.
    """
    global _WARM  # noqa: PLW0603 - once per process
    if _WARM:
        return
    _WARM = True
    offsets = np.zeros((AZURE_KINECT.n_joints, 3))
    for joint, parent in enumerate(AZURE_KINECT.parents):
        if parent >= 0:
            name = AZURE_KINECT.joint_names[joint]
            side = 0.1 if "Left" in name else -0.1 if "Right" in name else 0.0
            offsets[joint] = offsets[parent] + [side, -0.12, 0.05]
    camera = CameraCalibration(frame_id="warm_up", translation=np.array([0.0, 0.0, -3.0]))
    tracker = Tracker(
        TrackerParams(max_delay=0.0, min_hits=2, min_cameras=1),
        Calibration("warm_up", "world", {"warm_up": camera}),
    )
    for index in range(3):
        stamp = 1_000_000_000 + index * 33_333_333
        skeleton = Skeleton.from_positions(
            offsets + np.array([0.01 * index, 0.0, 0.0]),
            AZURE_KINECT,
            skeleton_id=1,
            src_time_ns=stamp,
        )
        tracker.update(SkeletonGroup(stamp, "warm_up", [skeleton]))
