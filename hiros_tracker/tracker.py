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

Modules: this one holds the front door (``Tracker``: buffering, restarts, the frame flow) and
its parameters; ``matching`` the per-frame association and update (steps 3 and the labelling),
``lifecycle`` confirmation, expiry and re-identification (step 4), ``layout_info`` what is
derived from a layout (mirror parts, body frame, weights).
"""

from __future__ import annotations

import heapq
import itertools
from collections import deque
from dataclasses import dataclass

import numpy as np

from hiros_core.accounting import Accounted, Drops
from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.layouts import AZURE_KINECT, Layout
from hiros_core.limits import MAX_POSITION_M
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_tracker import kernels
from hiros_tracker.correction import CameraCorrection, MovedFrame
from hiros_tracker.kernel_args import StackedRows
from hiros_tracker.layout_info import (
    _body_frame,
    _joint_weights,
    _LayoutInfo,
    _mirror_parts,
    _side_arrays,
)
from hiros_tracker.lifecycle import MIN_SHAPE_LINKS, SHAPE_TOLERANCE, TrackLifecycle, _Lost
from hiros_tracker.matching import FrameMatching, _Detections
from hiros_tracker.tracks import TrackTable

__all__ = ["MIN_SHAPE_LINKS", "SHAPE_TOLERANCE", "Tracker", "TrackerParams", "warm_up"]


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
        facing_memory: seconds over which the facing evidence fades while the track walks.
        facing_memory_standing: the same while it stands (slower than ``walking_speed``):
            what a person's turn taught the track must outlast their standing with their back
            to the cameras, whose SDKs then report them facing the cameras detection after
            detection. A standing track that two cameras clearly contradict is turned
            within a second all the same (``facing.DOUBT_LIMIT``).
        facing_threshold: log-odds against the track's facing at which it is relabelled.
        walking_speed: m/s above which a person is taken to face where they walk.
        walking_evidence: log-odds added per detection for facing the walking direction.
        duplicate_distance: metres; a tentative track closer than this to a confirmed track
            when it would be confirmed is a duplicate body and is deleted.
        reid_timeout: seconds a lost track (every camera lost the person) is remembered: a
            new track starting within this of its last detection, near where it was and
            with the same body shape, re-takes its id (0: never; a person leaving the shared
            view and returning is then a new id). Gaps of over ``BLIND_GAP_S`` (1 s) with no
            frame from any camera (a paused recording) do not count.
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
    mirror_check: bool = True
    mirror_margin: float = 0.02
    mirror_vote: bool = True
    facing_check: bool = True
    flip_prior: float = 0.1
    flip_prior_back: float = 0.7
    facing_memory: float = 3.0
    facing_memory_standing: float = 30.0
    facing_threshold: float = 3.0
    walking_speed: float = 0.4
    walking_evidence: float = 1.0
    duplicate_distance: float = 0.25
    reid_timeout: float = 10.0
    reid_distance: float = 1.5
    joint_weight_decay: float = 0.5
    min_joints: int = 4
    min_confidence: float = 0.1


MIN_RESTART_S = 1.0
"""A frame older than the last processed one by more than ``track_timeout`` (and at least
this) is not late: its source restarted (a replayed recording, a restarted driver); every
track would have timed out over such a gap, and the tracker starts its time over."""


class Tracker(FrameMatching, TrackLifecycle, Accounted):
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
        self._blind: list[tuple[int, int]] = []  # gaps with no frame at all (_note_frame)
        self._last_frame_ns: int | None = None
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
        self._blind.clear()
        self._last_frame_ns = None
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
        assigned = self._match(table, found.positions, det_ids, stamp, code, info)
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
