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
from collections import deque
from dataclasses import dataclass
from functools import cache, cached_property
from typing import NamedTuple

import numpy as np
from scipy.optimize import linear_sum_assignment

from hiros_core.accounting import Accounted, Drops
from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.layouts import AZURE_KINECT, Layout
from hiros_core.limits import MAX_POSITION_M
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_tracker import kernels
from hiros_tracker.correction import CameraCorrection, MovedFrame
from hiros_tracker.kernel_args import (
    FacingBody,
    FacingPriors,
    FacingView,
    FrameRows,
    GateFrame,
    GateSettings,
    GateTracks,
    HitLayout,
    HitSettings,
    MatchSettings,
    MirrorLayout,
    SideLayout,
    StackedRows,
    TrackPoses,
    UpdateSettings,
)
from hiros_tracker.tracks import TrackTable

__all__ = ["Tracker", "TrackerParams"]

_NS = 1e-9
_NO_CAMERA = np.zeros(3)
"""Placeholder camera position for the facing kernel when the camera's pose is unknown."""


@dataclass
class TrackerParams:
    """Tracker parameters (field names = ROS parameter names of the ``tracker`` node).

    Attributes:
        max_delay: seconds a frame waits for late frames of other cameras before it is
            processed; frames older than the last processed one are dropped as ``late``.
        max_jump: seconds a frame's stamp may lie ahead of the newest frame so far. A frame
            further ahead is held until the next frame: kept if that one is far ahead too
            (every camera paused, or a gap in a recording), else dropped as ``stamp far
            ahead`` (one camera's clock glitch, which would otherwise hold the out-of-order
            buffer open and make every later frame of the other cameras ``late``).
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
        flip_episode: mean seconds an SDK keeps a body front/back flipped once it flips it;
            a camera's consecutive flipped detections then weigh as one event, so one
            camera's episode cannot outvote the others (0, the default: every detection
            independent). Off by default: 1.5 s lowers the demo's joint-angle RMSE 15.7 ->
            14.5 deg but raises the merged error of ``hiros bench tracking`` (4 people
            crossing) from 0.56 to 0.75 of the best camera's.
        flip_misread: chance that a detection's facing is misread (pointers across the body).
        facing_threshold: log-odds against the track's facing at which it is relabelled.
        walking_speed: m/s above which a person is taken to face where they walk.
        walking_evidence: log-odds added per detection for facing the walking direction.
        duplicate_distance: metres; a tentative track closer than this to a confirmed track
            when it would be confirmed is a duplicate body and is deleted.
        reid_timeout: seconds a lost track (every camera lost the person) is remembered: a
            new track starting within this of its last detection, near where it was and
            with the same body shape, re-takes its id (0: never; a person leaving the shared
            view and returning is then a new id).
        reid_distance: metres between where a lost track was last seen and where a new track
            is (root joints) within which the new one may re-take its id.
        joint_weight_decay: a joint's weight in the cost is this to the power of its depth in
            the skeleton tree (pelvis 1, hips 0.5, knees 0.25, ...): the body's core places a
            person; limbs swing, get occluded and are the first a flip throws off.
        min_joints: joints a detection and a track must share for a cost to exist.
        min_confidence: joints of lower confidence are left out of the cost (the SDK's NONE
            level, 0, marks joints outside the view).

    """

    max_delay: float = 0.05
    max_jump: float = 1.0
    gate_distance: float = 0.5
    gate_growth: float = 0.5
    min_hits: int = 8
    min_cameras: int = 2
    single_camera_confirm: float = 2.0
    tentative_timeout: float = 0.3
    track_timeout: float = 2.0
    recent_window: float = 0.2
    max_prediction: float = 0.5
    position_smoothing: float = 0.25
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
    flip_episode: float = 0.0
    flip_misread: float = 0.05
    facing_threshold: float = 3.0
    walking_speed: float = 0.4
    walking_evidence: float = 1.0
    duplicate_distance: float = 0.25
    reid_timeout: float = 10.0
    reid_distance: float = 1.5
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
    def arrays(self) -> MirrorLayout:
        """The parts as the kernels take them."""
        return MirrorLayout(self.part, self.mirror, self.count)

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

    @cached_property
    def parents(self) -> np.ndarray:
        """``(J,)`` each joint's parent, ``-1`` at the root."""
        return np.array(self.layout.parents, dtype=np.int64)

    @cached_property
    def usable(self) -> bool:
        """Whether the layout names the joints the facing check needs (``_BodyFrame.usable``)."""
        return bool(self.frame.usable)

    @cached_property
    def hit_layout(self) -> HitLayout:
        """What ``kernels.hit_frame`` needs of the layout: mirror parts, side pairs, body frame."""
        frame = self.frame
        body = FacingBody(
            frame.root, frame.neck, frame.left, frame.right, frame.pointers, self.parts.mirror
        )
        return HitLayout(self.parts.arrays, SideLayout(*self.sides), body)


class _Detections(NamedTuple):
    """A frame's detections the tracker can use (``Tracker._valid_detections``).

    ``positions`` ``(D, J, 3)`` (NaN where absent or below ``min_confidence``), ``kept``
    ``(D,)`` how many finite joints each keeps, ``index`` ``(D,)`` their rows in ``rows``
    (markers, presence, links, link presence): the frame's stack when ``stacked``, else
    new arrays of the markers and presence (twice), which labelling must not write to.
    """

    skeletons: list[Skeleton]
    positions: np.ndarray
    kept: np.ndarray
    index: np.ndarray
    rows: StackedRows
    stacked: bool


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


MIN_RESTART_S = 1.0
"""A frame older than the last processed one by more than ``track_timeout`` (and at least
this) is not late: its source restarted (a replayed recording, a restarted driver); every
track would have timed out over such a gap, and the tracker starts its time over."""


class Tracker(Accounted):
    """Gives every camera detection a persistent track id (see the module docstring).

    Attributes:
        params: the parameters it was built with.
        drops: reason -> count of input left out: whole frames (uncalibrated camera, late
            frame, ...) or detections (no finite joint, ...); see ``Accounted``.
        processed: frames released from the buffer and associated (``held``: still in it).
        correction: the calibration being applied (``set_calibration`` replaces it).

    """

    def __init__(
        self, params: TrackerParams | None = None, calibration: Calibration | None = None
    ) -> None:
        warm_up()
        self.params = params or TrackerParams()
        self.drops = Drops()
        self.correction = CameraCorrection(calibration, self.drops)
        self._table: TrackTable | None = None  # made for the first detections' joint count
        self._doomed: list[int] = []  # rows of duplicate tracks, removed at the frame's end
        self._lost: list[_Lost] = []  # expired confirmed tracks, for re-identification
        self._next_id = 0
        self._buffer: list[tuple[int, int, str, MovedFrame]] = []
        self._sequence = itertools.count()
        self._camera_codes: dict[str, int] = {}
        self._newest_ns: int | None = None
        self._released_ns: int | None = None
        self._suspect: tuple[int, str, MovedFrame] | None = None  # a frame far ahead, on hold
        self._recent: dict[str, deque[int]] = {}  # each camera's last stamps
        self._up = np.zeros(4)  # the world's up (x, y, z, known): see facing._update_up
        self._info: _LayoutInfo | None = None
        self._camera_positions: dict[str, tuple[CameraCalibration, np.ndarray]] = {}
        self.restarts = 0  # times a source's stamps went back past the tracks' timeout
        self._last_restart = ""

    def set_params(self, params: TrackerParams) -> None:
        """Track with ``params`` from the next frame on (tracks are kept).

        Every parameter is read per frame except ``joint_weight_decay`` (once per layout).
        """
        self.params = params

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
        table = self._table
        if table is None:
            return []
        return table.ids[: table.n][table.confirmed[: table.n]].tolist()

    @property
    def pending(self) -> int:
        """Frames waiting in the out-of-order buffer (or held for a stamp far ahead)."""
        return len(self._buffer) + (self._suspect is not None)

    @property
    def held(self) -> int:  # type: ignore[override]
        """``pending``: the frames of the frame balance not processed nor dropped yet."""
        return self.pending

    # ----------------------------------------------------------------------------------- flow
    def update(self, group: SkeletonGroup) -> SkeletonGroup:
        """Take one camera frame; return the detections released by it, with track ids.

        The returned group holds every detection of confirmed tracks from the frames released
        by this call (zero or more frames, in reference-time order): world frame, header stamp
        = the last released frame's corrected stamp.
        """
        corrected = self.correction.move(group)
        if corrected is None:
            return self._output([])
        self._mask_unusable_joints(corrected)
        stamp_ns = corrected.group.stamp_ns
        camera = corrected.camera or group.camera
        restart_ns = round(max(self.params.track_timeout, MIN_RESTART_S) * 1e9)
        if self._released_ns is not None and self._released_ns - stamp_ns > restart_ns:
            return self._start_over(stamp_ns, camera, corrected)
        if self._seen_before(camera, stamp_ns):
            self.drops.frame("duplicate frame")
            return self._output([])
        if self._released_ns is not None and stamp_ns < self._released_ns:
            self.drops.frame("late frame")
            return self._output([])
        jump_ns = round(self.params.max_jump * 1e9)
        if self._suspect is not None:
            held, self._suspect = self._suspect, None
            if stamp_ns > self._newest_ns + jump_ns:  # type: ignore[operator]
                self._buffered(*held)  # confirmed: every clock moved on
            else:
                self.drops.frame("stamp far ahead")
        if self._newest_ns is not None and stamp_ns > self._newest_ns + jump_ns:
            self._suspect = (stamp_ns, camera, corrected)
            return self._output([])
        self._buffered(stamp_ns, camera, corrected)
        return self._release(self._newest_ns - round(self.params.max_delay * 1e9))  # type: ignore[operator]

    def flush(self) -> SkeletonGroup:
        """Process every buffered frame now (end of a recording), a held one included."""
        if self._suspect is not None:
            self._buffered(*self._suspect)
            self._suspect = None
        return self._release(None)

    def _mask_unusable_joints(self, frame: MovedFrame) -> None:
        """Mark absent (counted) the present joints that are not finite or absurdly far.

        NaN and infinite joints otherwise reached ``/hiros/tracker`` marked present, and a
        joint at 1e30 m made its detection vanish in the gating without a count. Far is past
        ``hiros_core.limits.MAX_POSITION_M`` in the world frame. A stacked frame is checked
        in one pass over its rows, which its skeletons are views of.
        """
        stack = frame.stack
        rows = (
            [(stack.markers, stack.marker_present)]
            if stack is not None
            else [(s.markers[None], s.marker_present[None]) for s in frame.group.skeletons]
        )
        for markers, present in rows:
            positions = markers[..., 1:4]  # a marker row's x, y, z (as in kernels)
            bad = present & ~(np.abs(positions) < MAX_POSITION_M).all(axis=-1)  # NaN too
            if not bad.any():
                continue
            finite = np.isfinite(positions).all(axis=-1)
            self.drops.detections("nan joint", int((bad & ~finite).sum()))
            self.drops.detections("joint too far", int((bad & finite).sum()))
            present[bad] = False

    def _start_over(self, stamp_ns: int, camera: str, frame: MovedFrame) -> SkeletonGroup:
        """A frame far older than the processed ones: its source restarted; time starts over.

        A replayed recording (``hiros play --loop``, a second ``hiros play``) or a driver
        restarted with its clock sends stamps far behind; taken as late frames, every one
        was dropped and the output stopped for good. The frames still buffered are processed
        (their output is returned), the tracks and time state are forgotten (new tracks get
        new ids) and ``restarts`` counts the event for ``/diagnostics``; ``frame`` is the
        first of the new time.
        """
        flushed = self.flush()
        self._newest_ns = self._released_ns = None
        self._recent.clear()
        self._table = None
        self._lost.clear()
        self.restarts += 1
        self._last_restart = f"{camera} went back {(flushed.stamp_ns - stamp_ns) / 1e9:.1f} s"
        self._seen_before(camera, stamp_ns)
        self._buffered(stamp_ns, camera, frame)
        return flushed

    def diagnostics(self) -> dict[str, str]:
        """``restarts``: how often time started over, and why the last time (if ever)."""
        if not self.restarts:
            return {}
        return {"restarts": f"{self.restarts} (last: {self._last_restart})"}

    def _seen_before(self, camera: str, stamp_ns: int) -> bool:
        """Whether this camera already sent a frame with this stamp (among its last 64)."""
        recent = self._recent.get(camera)
        if recent is None:
            recent = self._recent[camera] = deque(maxlen=64)
        if stamp_ns in recent:
            return True
        recent.append(stamp_ns)
        return False

    def _buffered(self, stamp_ns: int, camera: str, frame: MovedFrame) -> None:
        heapq.heappush(self._buffer, (stamp_ns, next(self._sequence), camera, frame))
        if self._newest_ns is None or stamp_ns > self._newest_ns:
            self._newest_ns = stamp_ns

    def _release(self, horizon_ns: int | None) -> SkeletonGroup:
        skeletons: list[Skeleton] = []
        while self._buffer and (horizon_ns is None or self._buffer[0][0] <= horizon_ns):
            stamp_ns, _, camera, frame = heapq.heappop(self._buffer)
            self._released_ns = stamp_ns
            skeletons.extend(self._process(frame, camera))
            self.processed += 1  # (after: a frame whose processing raised is not processed)
        return self._output(skeletons)

    def _output(self, skeletons: list[Skeleton]) -> SkeletonGroup:
        stamp = self._released_ns if self._released_ns is not None else 0
        return SkeletonGroup(stamp, self.correction.world_frame, skeletons)

    # ---------------------------------------------------------------------------- association
    def _process(self, frame: MovedFrame, camera: str) -> list[Skeleton]:
        """Associate one world-frame camera frame with the tracks; return confirmed outputs."""
        code = self._camera_codes.setdefault(camera, len(self._camera_codes))
        self._expire(frame.group.stamp_ns)
        found = self._valid_detections(frame)
        if found is None:
            return []
        detections = found.skeletons
        info = self._layout_info(detections[0].layout)
        table = self._tracks_for(found.positions.shape[1], code)
        stamp = detections[0].src_time_ns
        det_ids = np.array([d.id for d in detections], dtype=np.int64)
        assigned = self._match(table, detections, found.positions, det_ids, stamp, code, info)
        pairs = self._pairs(table, *assigned, found, stamp)
        if not len(pairs[0]):
            return []
        flips, track_ids, labelled = self._hit(
            table, found, det_ids, pairs, info, stamp, code, self._camera_position(camera)
        )
        output = self._labelled(found, pairs, flips, track_ids, labelled, info.parts)
        self._remove_doomed()
        return output

    def _valid_detections(self, frame: MovedFrame) -> _Detections | None:
        """Skeletons with a finite joint and the layout of the first one (and of the tracks).

        None when there are none; else see ``_Detections``. With the frame's rows stacked
        (``frame.stack``), the detections' rows are in it; else in new arrays.
        """
        skeletons = frame.group.skeletons
        if not skeletons:
            return None
        stack = frame.stack
        if stack is not None:
            markers, present = stack.markers, stack.marker_present
            rows = StackedRows(markers, present, stack.links, stack.link_present)
        else:
            skeletons = self._one_layout(skeletons)
            if not skeletons:
                return None
            markers = np.array([s.markers for s in skeletons])
            present = np.array([s.marker_present for s in skeletons])
            rows = StackedRows(markers, present, markers, present)  # links never labelled here
        positions, usable, kept, unusable = kernels.masked_positions(
            markers, present, self.params.min_confidence
        )
        index = np.arange(len(skeletons))
        if unusable:
            self.drops.detections("no finite joint", unusable)
            skeletons = [s for s, ok in zip(skeletons, usable.tolist(), strict=True) if ok]
            positions, kept, index = positions[usable], kept[usable], index[usable]
        if not skeletons:
            return None
        table = self._table
        if table is not None and table.n and positions.shape[1] != table.n_joints:
            self.drops.detections("layout differs from the tracks", len(skeletons))
            return None
        return _Detections(skeletons, positions, kept, index, rows, stack is not None)

    def _one_layout(self, skeletons: list[Skeleton]) -> list[Skeleton]:
        """Skeletons of the first usable one's layout (the others dropped, counted)."""
        valid: list[Skeleton] = []
        for skeleton in skeletons:
            if valid and skeleton.layout is not valid[0].layout:
                self.drops.detections("layout differs within a frame")
            elif not (skeleton.marker_present & np.isfinite(skeleton.positions).all(1)).any():
                self.drops.detections("no finite joint")
            else:
                valid.append(skeleton)
        return valid

    def _tracks_for(self, n_joints: int, camera: int) -> TrackTable:
        """The track table, (re)made for ``n_joints`` when empty, holding camera code ``camera``."""
        table = self._table
        if table is None or (not table.n and table.n_joints != n_joints):
            table = self._table = TrackTable(n_joints, len(self._camera_codes))
        table.ensure_cameras(camera + 1)
        return table

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

    def _match(  # noqa: PLR0917
        self,
        table: TrackTable,
        detections: list[Skeleton],
        positions: np.ndarray,
        det_ids: np.ndarray,
        stamp: int,
        camera: int,
        info: _LayoutInfo,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Assign detections to tracks in a cascade (DeepSORT-like), each level optimally.

        Levels: confirmed tracks seen within ``recent_window``, other confirmed tracks,
        tentative tracks (``kernels.gate_costs``): a track that has just lost its person (who
        left, or whom every camera lost) must not take a detection that a live track explains.

        Returns:
            the solver's pairs, ``(N,)`` track rows and ``(N,)`` detections (those not
            ``(T, D)`` feasible left to ``kernels.frame_pairs``), the feasible pairs and
            ``(T, D, K)`` the mirrored parts of every pair.

        """
        cost, flips, feasible, levels = self._costs(table, detections, positions, det_ids,
                                                    stamp, camera, info)  # fmt: skip
        n_tracks, n_det = cost.shape
        track_levels = levels.tolist()
        if n_tracks and min(track_levels) == max(track_levels):  # one level (usual): one solve
            r, c = linear_sum_assignment(cost)
            return r, c, feasible, flips
        matched = [-1] * n_det
        free = list(range(n_det))
        for level in range(3):
            rows = [t for t, at in enumerate(track_levels) if at == level]
            if not rows or not free:
                continue
            whole = len(rows) == n_tracks and len(free) == n_det
            allowed = feasible if whole else feasible[rows][:, free]
            r, c = linear_sum_assignment(cost if whole else cost[rows][:, free])
            for i, j in zip(r.tolist(), c.tolist(), strict=True):
                if allowed[i, j]:
                    matched[free[j]] = rows[i]
            free = [d for d in free if matched[d] < 0]
        dets = [d for d, row in enumerate(matched) if row >= 0]
        r = np.array([matched[d] for d in dets], dtype=np.int64)
        return r, np.array(dets, dtype=np.int64), feasible, flips

    def _costs(  # noqa: PLR0917
        self,
        table: TrackTable,
        detections: list[Skeleton],
        positions: np.ndarray,
        det_ids: np.ndarray,
        stamp: int,
        camera: int,
        info: _LayoutInfo,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every (track, detection) pair's cost, flips, feasibility and the tracks' levels.

        Each pair's cost is independent of the others, so the whole matrix is computed once
        per frame and each cascade level takes its rows.
        """
        params = self.params
        parts = info.parts.arrays
        n = table.n
        tracks = TrackPoses(table.positions[:n], table.velocity[:n], table.time_ns[:n])
        match = MatchSettings(
            params.max_prediction, params.mirror_check, params.min_joints, params.mirror_margin
        )
        gate_tracks = GateTracks(table.last_hit_ns, table.confirmed, table.body_ids, table.seen)
        frame = GateFrame(det_ids, camera, stamp, stamp - round(params.recent_window * 1e9))
        gate = GateSettings(params.body_id_bonus, params.gate_distance, params.gate_growth)
        if params.velocity_weight <= 0 and params.orientation_weight <= 0:
            return kernels.frame_costs(
                tracks, positions, info.weights, parts, match, gate_tracks, frame, gate
            )
        cost, flips = kernels.match_costs(tracks, positions, stamp, info.weights, parts, match)
        cost = cost + self._motion_costs(table, detections, info.parts, flips)
        feasible, levels = kernels.gate_costs(cost, gate_tracks, frame, gate)
        return cost, flips, feasible, levels

    def _motion_costs(
        self,
        table: TrackTable,
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
            track_v = table.velocities[: table.n, None]
            cost += params.velocity_weight * _nan_mean(np.linalg.norm(det_v - track_v, axis=3))
        if params.orientation_weight > 0:
            det_q = np.array([d.orientations for d in detections])[pick, order]
            track_q = table.orientations[: table.n, None]
            dot = np.abs((det_q * track_q).sum(axis=3))
            angle = 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))
            cost += params.orientation_weight * _nan_mean(angle)
        return cost

    def _pairs(  # noqa: PLR0917
        self,
        table: TrackTable,
        r: np.ndarray,
        c: np.ndarray,
        feasible: np.ndarray,
        flips: np.ndarray,
        found: _Detections,
        stamp: int,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each detection's track: its match, else a new tentative track if it has the joints.

        Returns ``(U,)`` track rows, ``(U,)`` their detections (in detection order, so new
        tracks are made in that order) and ``(U, K)`` the parts to relabel in each.
        """
        rows, dets, pair_flips, new, dropped = kernels.frame_pairs(
            r, c, feasible, flips, found.kept, self.params.min_joints
        )
        if dropped:
            self.drops.detections("too few joints", dropped)
        if new:
            for u in np.flatnonzero(rows < 0).tolist():
                rows[u] = table.add(self._next_id, found.positions[dets[u]], stamp)
                self._next_id += 1
        return rows, dets, pair_flips

    # -------------------------------------------------------------------------------- updates
    def _hit(  # noqa: PLR0917 - one frame's matched pairs, all positional for brevity
        self,
        table: TrackTable,
        found: _Detections,
        det_ids: np.ndarray,
        pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
        info: _LayoutInfo,
        time_ns: int,
        camera: int,
        camera_position: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """Fold one frame's detections into the tracks (``kernels.hit_frame``), confirm them.

        Args:
            table: the tracks.
            found: the frame's detections.
            det_ids: ``(D,)`` the camera's body ids of the detections.
            pairs: ``(U,)`` the rows of the tracks hit (distinct), ``(U,)`` their detections
                and ``(U, K)`` the parts to relabel in each (``_pairs``).
            info: the layout's mirror parts, weights and body frame.
            time_ns: the frame's corrected stamp.
            camera: the frame's camera code.
            camera_position: ``(3,)`` the camera's position in the world, None if unknown.

        Returns:
            ``(U, K)`` the parts to relabel in each detection's output (the detection's own
            flips and its hips, eyes and ears put on its shoulders' side, then the swaps its
            track made: facing check or mirror vote), ``(U,)`` the track ids and whether the
            detections are labelled already (every track confirmed; else ``_labelled`` does).

        """
        params = self.params
        rows = pairs[0]
        facing = params.mirror_check and params.facing_check and info.usable
        voting = params.mirror_check and params.mirror_vote and not facing
        update = UpdateSettings(
            float(params.position_smoothing),
            float(params.max_prediction),
            round(params.velocity_window * 1e9),
            info.weights,
        )
        settings = HitSettings(
            update,
            align=params.mirror_check and params.facing_check,
            orient=params.orientation_weight > 0,
            weigh=facing,
            label=found.stacked and not voting,
            priors=self._priors,
        )
        frame = FrameRows(found.positions, det_ids, found.index, found.rows)
        flips, full, turned, n_turned, track_ids, labelled = kernels.hit_frame(
            table.hit_fields(),
            frame,
            pairs,
            self._view(camera, time_ns, camera_position),
            info.hit_layout,
            settings,
        )
        if full:
            table.grow_records()
        table.learn_limbs(rows, found.positions[pairs[1]], info.parents)
        if n_turned:
            self._turned(table, rows[turned])
        if labelled or (not voting and table.confirmed[rows].all()):
            return flips, track_ids, labelled
        confirmed, hits = table.confirmed[rows].tolist(), table.hits[rows].tolist()
        for u, row in enumerate(rows.tolist()):
            if not confirmed[u] and hits[u] >= params.min_hits:
                self._confirm(table, row, info, time_ns)
                track_ids[u] = table.ids[row]  # re-identified: an older id
            if voting and table.confirmed[row]:
                flips[u] ^= self._vote(table, row, info.parts, camera, time_ns, flips[u].copy())
        return flips, track_ids, False

    def _view(self, camera: int, time_ns: int, camera_position: np.ndarray | None) -> FacingView:
        """Where ``kernels.turn_facing`` judges a frame's facing from: up, camera, stamp."""
        position = _NO_CAMERA if camera_position is None else camera_position
        return FacingView(self._up, position, camera_position is not None, camera, time_ns)

    @property
    def _priors(self) -> FacingPriors:
        """The facing check's settings, as ``kernels.turn_facing`` takes them."""
        params = self.params
        return FacingPriors(
            params.flip_prior,
            params.flip_prior_back,
            params.walking_speed,
            params.walking_evidence,
            params.facing_memory,
            params.facing_threshold,
            params.flip_episode,
            params.flip_misread,
        )

    @staticmethod
    def _turned(table: TrackTable, rows: np.ndarray) -> None:
        """The votes of tracks the facing check relabelled, turned with them."""
        for row in rows.tolist():
            votes = table.votes[row]
            table.votes[row] = {cam: (t, ~vote) for cam, (t, vote) in votes.items()}
            table.mirrored[row] = {cam for cam, (_, vote) in table.votes[row].items() if vote.any()}

    def _vote(  # noqa: PLR0917
        self,
        table: TrackTable,
        row: int,
        parts: _MirrorParts,
        camera: int,
        time_ns: int,
        flips: np.ndarray,
    ) -> np.ndarray:
        """Swap a track's sides of the parts that most cameras seeing it now call mirrored.

        The fallback for layouts without the joints the facing check needs.
        """
        votes, mirrored = table.votes[row], table.mirrored[row]
        votes[camera] = (time_ns, flips)
        if not flips.any():
            mirrored.discard(camera)
            if not mirrored:  # nobody calls the sides mirrored: nothing to count
                return np.zeros_like(flips)
        else:
            mirrored.add(camera)
        recent = time_ns - round(self.params.velocity_window * 1e9)
        recent_votes = [vote for t, vote in votes.values() if t >= recent]
        if len(recent_votes) < 2:
            return np.zeros_like(flips)
        swap = 2 * np.sum(recent_votes, axis=0) > len(recent_votes)
        if swap.any():
            table.relabel(row, parts.permutation(swap))
            table.votes[row] = {cam: (t, vote ^ swap) for cam, (t, vote) in votes.items()}
            table.mirrored[row] = {cam for cam, (_, vote) in table.votes[row].items() if vote.any()}
        return swap

    def _confirm(self, table: TrackTable, row: int, info: _LayoutInfo, time_ns: int) -> None:
        """Confirm a tentative track seen enough, unless it duplicates a confirmed one.

        A duplicate is a tentative track within ``duplicate_distance`` of a confirmed track,
        or near one (``2 * gate_distance``) and given, by every camera that saw both, the body
        id that camera gives the confirmed track: a camera's poor view of a person it already
        follows (its SDK says so), which a crowded, noisy moment pushed beyond the gate. A
        duplicate is removed at the end of the frame (``_remove_doomed``): rows stay put while
        the frame's pairs refer to them. A confirmed track may re-take the id of a lost one
        (``_reidentify``).
        """
        params = self.params
        cameras = min(params.min_cameras, max(len(self.correction.cameras), 1))
        old_enough = (time_ns - int(table.born_ns[row])) * _NS >= params.single_camera_confirm
        if int(table.seen[row].sum()) < cameras and not old_enough:
            return
        confirmed = np.flatnonzero(table.confirmed[: table.n])
        if len(confirmed):
            distance = self._distances(table, confirmed, row, info, time_ns)
            same_body = self._same_body_ids(table, confirmed, row)
            if (distance < params.duplicate_distance).any() or (
                same_body & (distance < 2.0 * params.gate_distance)
            ).any():
                self._doomed.append(row)
                self.drops.detections("duplicate of a confirmed track")
                return
        table.confirmed[row] = True
        self._reidentify(table, row, info)

    def _distances(
        self, table: TrackTable, rows: np.ndarray, row: int, info: _LayoutInfo, time_ns: int
    ) -> np.ndarray:
        """``(len(rows),)`` cost distance (m) of track ``row`` to tracks ``rows`` predicted."""
        params = self.params
        tracks = TrackPoses(table.positions[rows], table.velocity[rows], table.time_ns[rows])
        plain = MatchSettings(params.max_prediction, False, params.min_joints, 0.0)
        distance, _ = kernels.match_costs(
            tracks, table.positions[row][None], time_ns, info.weights, info.parts.arrays, plain
        )
        return distance[:, 0]

    @staticmethod
    def _same_body_ids(table: TrackTable, rows: np.ndarray, row: int) -> np.ndarray:
        """``(len(rows),)`` whether the cameras saw track ``row`` as each of ``rows``.

        True where at least one camera saw both tracks and every such camera gave both the
        same body id.
        """
        both = table.seen[rows] & table.seen[row]
        same = table.body_ids[rows] == table.body_ids[row]
        return both.any(axis=1) & ~(both & ~same).any(axis=1)

    def _reidentify(self, table: TrackTable, row: int, info: _LayoutInfo) -> None:
        """Give a newly confirmed track the id of the lost track it continues, if any.

        A person whom every camera lost (out of the shared view, hidden, or a turn the
        motion model missed) comes back as a new track. It re-takes the id of a lost track
        when that track was last seen within ``reid_timeout`` before the new one was born
        (never seen beside it), within ``reid_distance`` of where the new one is (root joint)
        and with the same body shape (``_same_shape``); of several, the nearest. A lost track
        is a confirmed one still live but unseen since the new one was born (it is removed)
        or one that expired (``_expire`` keeps it in ``_lost``).
        """
        params = self.params
        if params.reid_timeout <= 0:
            return
        born = int(table.born_ns[row])
        earliest = born - round(params.reid_timeout * 1e9)
        here = _centre(table.positions[row], info.frame.root)
        live = [
            _Lost(int(table.ids[k]), int(table.last_hit_ns[k]), table.positions[k].copy(),
                  table.limbs[k].copy(), table.limb_count[k].copy(), k)
            for k in np.flatnonzero(table.confirmed[: table.n]).tolist()
            if k != row and earliest <= table.last_hit_ns[k] < born and k not in self._doomed
        ]  # fmt: skip
        best, nearest = None, params.reid_distance
        for lost in [*live, *self._lost]:
            if not earliest <= lost.last_hit_ns < born:
                continue
            distance = float(np.linalg.norm(_centre(lost.positions, info.frame.root) - here))
            if distance <= nearest and _same_shape(lost, table.limbs[row], table.limb_count[row]):
                best, nearest = lost, distance
        if best is None:
            return
        table.ids[row] = best.track_id
        if best.row >= 0:
            self._doomed.append(best.row)
        else:
            self._lost.remove(best)

    def _remove_doomed(self) -> None:
        """Remove the duplicate tracks ``_confirm`` found and the tracks re-identified."""
        if self._doomed and self._table is not None:
            keep = np.ones(self._table.n, dtype=bool)
            keep[self._doomed] = False
            self._table.keep(keep)
            self._doomed.clear()

    def _expire(self, now_ns: int) -> None:
        """Remove the tracks not hit within their timeout; keep confirmed ones as lost."""
        table, params = self._table, self.params
        horizon = now_ns - round(params.reid_timeout * 1e9)
        self._lost = [lost for lost in self._lost if lost.last_hit_ns >= horizon]
        if table is None or not table.n:
            return
        count, keep = kernels.live_tracks(
            table.last_hit_ns,
            table.confirmed,
            table.n,
            now_ns,
            params.track_timeout,
            params.tentative_timeout,
        )
        if count < table.n:
            if params.reid_timeout > 0:
                gone = np.flatnonzero(~keep & table.confirmed[: table.n]).tolist()
                self._lost.extend(
                    _Lost(int(table.ids[k]), int(table.last_hit_ns[k]), table.positions[k].copy(),
                          table.limbs[k].copy(), table.limb_count[k].copy())
                    for k in gone
                )  # fmt: skip
            table.keep(keep)

    def _labelled(  # noqa: PLR0917
        self,
        found: _Detections,
        pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
        flips: np.ndarray,
        track_ids: np.ndarray,
        labelled: bool,
        parts: _MirrorParts,
    ) -> list[Skeleton]:
        """The output skeletons of the detections of confirmed tracks: track id, sides fixed.

        The detections are the tracker's own copies (made by the correction), so they are
        changed in place: the parts in ``flips`` ``(U, K)`` relabelled (links too: link ids are
        child joint ids), present joints without a velocity given their track's (track
        ``rows[u]``). ``hit_frame`` did that when ``labelled``; else it takes one compiled call
        with the frame's rows stacked, one per detection without.
        """
        table = self._table
        rows, dets, _ = pairs
        detections = found.skeletons
        if len(dets) < len(detections):
            detections = [detections[det] for det in dets.tolist()]
        if labelled:  # every track confirmed: the usual frame
            for detection, track_id in zip(detections, track_ids.tolist(), strict=True):
                detection.id = track_id
            return detections
        if found.stacked:
            kernels.label_frame(
                found.rows,
                found.index[dets],
                flips,
                parts.arrays,
                table.velocities,
                rows,
                table.confirmed,
            )
        output = []
        confirmed = table.confirmed[rows].tolist()
        for u, (detection, row) in enumerate(zip(detections, rows.tolist(), strict=True)):
            if not confirmed[u]:
                continue
            if not found.stacked:
                kernels.label_rows(
                    detection.markers,
                    detection.marker_present,
                    detection.links,
                    detection.link_present,
                    flips[u],
                    parts.arrays,
                    table.velocities[row],
                )
            detection.id = int(track_ids[u])
            output.append(detection)
        return output


def _nan_mean(values: np.ndarray) -> np.ndarray:
    """Mean over the last axis ignoring NaN; 0 where all are NaN."""
    finite = np.isfinite(values)
    return np.where(finite, values, 0.0).sum(axis=-1) / np.maximum(finite.sum(axis=-1), 1)


class _Lost(NamedTuple):
    """A confirmed track whom every camera lost: what re-identifies the person returning.

    ``positions`` ``(J, 3)`` its pose when last seen (``last_hit_ns``), ``limbs``/``counts``
    ``(J,)`` its link lengths (``TrackTable.limbs``), ``row`` its row while it is still live
    (else -1).
    """

    track_id: int
    last_hit_ns: int
    positions: np.ndarray
    limbs: np.ndarray
    counts: np.ndarray
    row: int = -1


SHAPE_TOLERANCE = 0.1
"""Relative difference of the median link length beyond which two tracks are other people:
wider than the mean of a few noisy detections strays (a few %), narrower than what sets
people apart clearly (a child, another build)."""
MIN_SHAPE_LINKS = 4
"""Links both tracks must have measured for their shapes to be compared at all."""


def _centre(positions: np.ndarray, root: int) -> np.ndarray:
    """``(3,)`` a pose's root joint, else the mean of its known joints."""
    if np.isfinite(positions[root]).all():
        return positions[root]
    return np.nanmean(positions, axis=0)


def _same_shape(lost: _Lost, limbs: np.ndarray, counts: np.ndarray) -> bool:
    """Whether a lost track's link lengths and a new track's agree (``SHAPE_TOLERANCE``).

    The median over the links both measured of their length ratio: hands, thumbs and the
    face, noisy or unseen, cannot sway it. Too few links in common say nothing against.
    """
    both = (lost.counts > 0) & (counts > 0) & (lost.limbs > 0) & (limbs > 0)
    if both.sum() < MIN_SHAPE_LINKS:
        return True
    ratio = float(np.median(np.log(limbs[both] / lost.limbs[both])))
    return abs(ratio) <= np.log1p(SHAPE_TOLERANCE)


_WARM = False


def warm_up() -> None:
    """Compile the kernels (or load them from numba's disk cache) once per process.

    The first ``Tracker`` of a process calls it, so that a live node pays the cost (about
    0.3 s from the cache, 10-20 s on the very first run after an install or a kernel change)
    before its first frame rather than on it: a burst of frames arriving during that first
    frame would otherwise overflow the subscription queue. A throwaway tracker follows two
    standing people seen by a calibrated camera through every code path a frame takes (two,
    so that a track is confirmed beside a confirmed one).
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
    apart = np.array([[0.0, 0.0, 0.0], [1.5, 0.0, 0.0]])  # two people 1.5 m apart
    for index in range(3):
        stamp = 1_000_000_000 + index * 33_333_333
        people = Skeleton.many_from_positions(
            offsets + apart[:, None] + np.array([0.01 * index, 0.0, 0.0]),
            AZURE_KINECT,
            skeleton_ids=[1, 2],
            src_time_ns=stamp,
        )
        tracker.update(SkeletonGroup(stamp, "warm_up", people))
