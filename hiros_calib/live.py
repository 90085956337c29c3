"""Live calibration: a sliding window of frames, estimates that keep refining, change detection.

:class:`LiveCalibrator` is what the ``calib`` node runs. Frames go in through :meth:`update`
(cheap, thread-safe); :meth:`step` does the work when it is due:

- every ``update_period`` seconds, a full :class:`~hiros_calib.calibrator.Calibrator` run
  over the window; a camera's new estimate that agrees with the current one replaces it while
  the window still holds all the data the current one rests on (after the start or a
  recalibration), and is blended in (``blend``) once frames slide out, so the calibration
  keeps refining as data accumulate;
- every ``check_period`` seconds, a cheap check of the last ``CHECK_LENGTH`` seconds: with the
  current calibration, the same people seen by two cameras should land on the same points.
  When every pair a camera belongs to disagrees by more than ``MOVED_RATIO`` times its usual
  residual (and ``moved_floor``), or its joints are all displaced the same way by more than
  ``moved_shift``, the camera was moved or its clock jumped: its older frames are dropped and
  it is recalibrated from ``recalibrate_after`` seconds of new data;
- a camera that sends nothing for ``silent_after`` seconds is reported (an event, and in
  :meth:`LiveCalibrator.snapshot`), and so is its return; its calibration is kept;
- an estimate that disagrees with the current one is not thrown away for good: it replaces
  the current one when it rests on more of the same frames (a recalibration from a few
  seconds can be wrong, e.g. turned 180° for cameras facing each other), or when
  ``REPLACE_AFTER`` estimates in a row disagree with the current one and agree with each
  other and the newest fits its frames clearly better (``REPLACE_MARGIN``): the current one
  is wrong, or the camera changed in a way the check missed.

All times are nanoseconds on the receiver's clock (``arrival_ns``) except the frames' own
stamps, which stay on their camera clocks.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from hiros_calib.calibrator import Calibrator, CalibratorParams
from hiros_calib.extrinsics import Correspondences, pair_correspondences
from hiros_calib.sync import CameraClock
from hiros_calib.tracks import BodyTrack, extract_tracks
from hiros_calib.world import place_in_world
from hiros_core.accounting import Accounted, Drops
from hiros_core.calibration import Calibration, CameraCalibration, load_calibration
from hiros_core.errors import CalibrationError
from hiros_core.geometry import RigidTransform
from hiros_core.model import SkeletonGroup

__all__ = [
    "AGREE_ROTATION",
    "AGREE_TIME",
    "AGREE_TRANSLATION",
    "CHECK_LENGTH",
    "EVENTS_KEPT",
    "MAX_FRAME_RATE",
    "MOVED_RATIO",
    "REPLACE_AFTER",
    "REPLACE_MARGIN",
    "RESTART_AFTER_BACKWARDS",
    "LiveCalibrator",
    "LiveCalibratorParams",
]

EVENTS_KEPT = 500
"""The newest events a :class:`LiveCalibrator` keeps. A node logs each as it comes; one that
runs for weeks must not keep every "not calibrated yet" of every estimate (a few kB each,
six a minute)."""

MAX_FRAME_RATE = 120.0
"""Frames per second of ``buffer_length`` a camera's window holds at most (twice the fastest
body-tracking rate we know of). The window is otherwise bounded by stamps only: a camera
whose stamps crept forward by microseconds would fill it without end, and an estimate's
arrays grow with it. The oldest frames beyond it leave the window (``window_over_rate``)."""


AGREE_TIME: float = 0.02
"""A new clock estimate within this (s) of the current one agrees with it."""

AGREE_ROTATION: float = 2.0
"""A new pose estimate within this rotation (deg) and ``AGREE_TRANSLATION`` of the current one
agrees with it."""

AGREE_TRANSLATION: float = 0.1
"""A new pose estimate within this translation (m) and ``AGREE_ROTATION`` of the current one
agrees with it."""

CHECK_LENGTH: float = 3.0
"""Seconds of the newest frames a check looks at."""

MOVED_RATIO: float = 2.5
"""A pair residual this many times its usual value flags a change, if it also exceeds
``moved_floor``."""

REPLACE_AFTER: int = 2
"""Estimates in a row that disagree with the current one (and agree with each other) before
the newest replaces it ..."""

REPLACE_MARGIN: float = 0.1
"""... if it also fits the frames it came from this much better (relative drop of its
camera's median joint distance): data that cannot pin a pose down (one person walking on the
spot) would otherwise let a consistent but wrong estimate replace a right one."""

RESTART_AFTER_BACKWARDS: float = 1.0
"""A frame stamped this many seconds before its camera's newest one starts the camera's
buffer again (its clock restarted, or the newest frame was a glitch); a smaller step back
is dropped as ``out_of_order``."""


@dataclass
class LiveCalibratorParams(CalibratorParams):
    """Every parameter of the ``calib`` node: calibration ones plus the live schedule."""

    buffer_length: float = 60.0
    """Seconds of frames kept per camera (the sliding window)."""
    first_estimate_after: float = 20.0
    """Seconds of frames needed before the first estimate."""
    update_period: float = 10.0
    """Seconds between full re-estimates."""
    blend: float = 0.3
    """Weight of a new estimate that agrees with the current one once the window slides (1:
    replace); while the window is still filling, a new estimate replaces the current one."""
    check_period: float = 1.0
    """Seconds between moved-camera checks."""
    moved_floor: float = 0.12
    """A pair residual ``MOVED_RATIO`` times its usual value flags a change if it also exceeds
    this (m)."""
    moved_shift: float = 0.12
    """A pair whose joints are displaced the same way by more than this (m; the length of the
    per-axis median of the residual vectors) flags a change too. A knock of 2° moves every
    joint ~10 cm the same way, which hardly shows in the median distance, set by the SDKs'
    noise (~12 cm), but stands out of the median displacement (3-6 cm unmoved, on the
    simulator)."""
    recalibrate_after: float = 5.0
    """Seconds of frames after a change before the camera is recalibrated."""
    silent_after: float = 5.0
    """Seconds without a frame from a camera before it is reported silent (an event, and in
    :meth:`LiveCalibrator.snapshot`); its calibration is kept, and its return is reported."""
    poses_from: str = ""
    """A calibration file of the same cameras, unmoved (calibrated from people walking across
    the area): its poses and world are kept and only the clocks are estimated, so people who
    stay on one spot (exercising) can be timed. A camera it no longer fits (moved since) is
    reported by a flagged estimate. Empty: the poses are estimated too."""


def _blend(old: CameraCalibration, new: CameraCalibration, weight: float) -> CameraCalibration:
    """``old`` moved ``weight`` of the way to ``new`` (slerp for the rotation)."""
    rotations = Rotation.from_quat([old.rotation, new.rotation])
    rotation = Slerp([0.0, 1.0], rotations)([weight]).as_quat()[0]
    # the offsets are compared at the same epoch so that a drift term does not leak in
    at = new.drift_epoch
    old_offset = old.time_offset + old.drift * (at - old.drift_epoch)
    return CameraCalibration(
        frame_id=new.frame_id,
        time_offset=old_offset + weight * (new.time_offset - old_offset),
        drift=old.drift + weight * (new.drift - old.drift),
        drift_epoch=at,
        translation=old.translation + weight * (new.translation - old.translation),
        rotation=rotation if rotation[3] >= 0 else -rotation,
        quality=dict(new.quality),
    )


def _difference(old: CameraCalibration, new: CameraCalibration) -> tuple[float, float, float]:
    """Clock (s, at the new estimate's epoch), rotation (deg) and translation (m) apart."""
    at = new.drift_epoch
    old_offset = old.time_offset + old.drift * (at - old.drift_epoch)
    angle = math.degrees((old.extrinsics.rotation.inv() * new.extrinsics.rotation).magnitude())
    distance = float(np.linalg.norm(old.translation - new.translation))
    return abs(old_offset - new.time_offset), angle, distance


def _agrees(old: CameraCalibration, new: CameraCalibration) -> bool:
    clock, angle, distance = _difference(old, new)
    return clock <= AGREE_TIME and angle <= AGREE_ROTATION and distance <= AGREE_TRANSLATION


def _clock(name: str, cam: CameraCalibration) -> CameraClock:
    return CameraClock(name, "ok", "", cam.time_offset, cam.drift, cam.drift_epoch)


class LiveCalibrator(Accounted):
    """Sliding-window calibration that refines itself and notices moved cameras.

    Args:
        params: the parameters.
        calibration: a starting calibration (e.g. loaded from a file), or None.

    Attributes:
        calibration: the current calibration (cameras appear as they are calibrated).
        drops: counted drop reasons of the frames (frames: no frame id, out of order) and
            of the estimates (not frames: see ``Accounted``).
        processed: frames kept in the window.
        events: ``(receiver time ns, message)`` of what happened (cameras calibrated,
            estimates that failed, changes detected), the newest ``EVENTS_KEPT``;
            :meth:`events_since` hands out those not yet seen.
        event_count: events so far, kept or not.
        tally: events so far by kind: ``calibrated``, ``replaced``, ``moved``,
            ``restarted``, ``silent``.
        estimates: full calibrations of the window run so far.
        estimate_seconds: how long the last one took (wall time).

    """

    def __init__(
        self, params: LiveCalibratorParams | None = None, calibration: Calibration | None = None
    ) -> None:
        self.params = params or LiveCalibratorParams()
        self.calibration = calibration or Calibration(
            reference=self.params.reference, world_frame=self.params.world_frame
        )
        self.drops = Drops()
        self.events: deque[tuple[int, str]] = deque(maxlen=EVENTS_KEPT)
        self.event_count = 0
        self.tally: Counter[str] = Counter()
        self.estimates = 0
        self.estimate_seconds = 0.0
        self._events_lock = threading.Lock()  # events come from the input and worker threads
        self._frames: dict[str, deque[tuple[SkeletonGroup, int]]] = {}
        self._since: dict[str, int] = {}  # per camera: frames stamped earlier are ignored
        self._support: dict[str, int] = {}  # per camera: first stamp its estimate rests on
        self._changed: set[str] = set()  # cameras waiting for recalibration
        self._baseline: dict[tuple[str, str], float] = {}
        self._first_arrival: int | None = None
        self._last_estimate: int | None = None
        self._last_check: int | None = None
        self._changed_at: dict[str, int] = {}
        self._rivals: dict[str, list[CameraCalibration]] = {}  # disagreeing estimates in a row
        self._silent: dict[str, int] = {}  # camera -> arrival of its last frame before silence
        self._lock = threading.Lock()
        self._known = load_calibration(self.params.poses_from) if self.params.poses_from else None

    # -- input
    def update(self, group: SkeletonGroup, arrival_ns: int) -> SkeletonGroup:
        """Keep a camera frame (and when it arrived); returns it unchanged."""
        if not group.frame_id:
            self.drops.frame("no_frame_id")
            return group
        camera = group.camera
        horizon = round(self.params.buffer_length * 1e9)
        with self._lock:
            frames = self._frames.setdefault(camera, deque())
            if (
                frames
                and group.stamp_ns <= frames[-1][0].stamp_ns
                and not self._restarted(camera, frames, group.stamp_ns, arrival_ns)
            ):
                self.drops.frame("out_of_order")
                return group
            frames.append((group, arrival_ns))
            self.processed += 1
            if camera in self._silent:
                gap = (arrival_ns - self._silent.pop(camera)) * 1e-9
                self._event(arrival_ns, f"{camera}: frames again after {gap:.1f} s")
            while frames and frames[0][0].stamp_ns < group.stamp_ns - horizon:
                frames.popleft()
            if len(frames) > self.params.buffer_length * MAX_FRAME_RATE:
                frames.popleft()
                self.drops["window_over_rate"] += 1
            if self._first_arrival is None:
                self._first_arrival = arrival_ns
        return group

    def _restarted(self, camera: str, frames: deque, stamp_ns: int, arrival_ns: int) -> bool:
        """Empty the buffer of a camera whose stamps went far back; True if they did.

        Without it, a camera whose clock restarted (or that sent one frame stamped far in
        the future) had every later frame dropped as out of order, for good. A real change
        of the camera's clock offset is then found by ``check`` like a clock jump.
        """
        back = frames[-1][0].stamp_ns - stamp_ns
        if back <= RESTART_AFTER_BACKWARDS * 1e9:
            return False
        frames.clear()
        self._since.pop(camera, None)
        self.drops["stamps_went_back"] += 1
        self._event(
            arrival_ns,
            f"{camera}: stamps went back {back * 1e-9:.3g} s, buffer restarted",
            "restarted",
        )
        return True

    # -- work
    def step(self, now_ns: int) -> bool:
        """Run the check and the estimate that are due at ``now_ns``; True if anything changed."""
        params = self.params
        if self._first_arrival is None:
            return False
        changed = False
        if self._due(self._last_check, now_ns, params.check_period):
            self._last_check = now_ns
            self._note_silent(now_ns)
            if self.calibration.cameras:
                changed |= self.check(now_ns)
        recalibrate = any(
            now_ns - self._changed_at[c] >= params.recalibrate_after * 1e9 for c in self._changed
        )
        enough = now_ns - self._first_arrival >= params.first_estimate_after * 1e9
        if recalibrate or (enough and self._due(self._last_estimate, now_ns, params.update_period)):
            self._last_estimate = now_ns
            changed |= self.estimate(now_ns)
        return changed

    def _note_silent(self, now_ns: int) -> None:
        """Report cameras whose newest frame arrived more than ``silent_after`` s ago."""
        limit = round(self.params.silent_after * 1e9)
        with self._lock:
            newest = {c: f[-1][1] for c, f in self._frames.items() if f}
        for camera, arrival in sorted(newest.items()):
            if camera not in self._silent and now_ns - arrival > limit:
                self._silent[camera] = arrival
                self._event(
                    now_ns, f"{camera}: no frames for {(now_ns - arrival) * 1e-9:.1f} s", "silent"
                )

    @staticmethod
    def _due(last: int | None, now_ns: int, period: float) -> bool:
        return last is None or now_ns - last >= period * 1e9

    def _window(self, length: float | None = None) -> tuple[dict[str, list], dict[str, list]]:
        """Per camera the frames (after any change) and arrivals, optionally only the newest."""
        groups, arrivals = {}, {}
        with self._lock:
            for camera, frames in self._frames.items():
                if not frames:
                    continue
                start = self._since.get(camera, -1)
                if length is not None:
                    start = max(start, frames[-1][0].stamp_ns - round(length * 1e9))
                kept = [(g, a) for g, a in frames if g.stamp_ns >= start]
                if kept:
                    groups[camera] = [g for g, _ in kept]
                    arrivals[camera] = [a for _, a in kept]
        return groups, arrivals

    def estimate(self, now_ns: int = 0) -> bool:
        """A full calibration of the window, merged into the current one; True if it changed."""
        self.estimates += 1
        started = time.monotonic()
        try:
            return self._estimate(now_ns)
        finally:
            self.estimate_seconds = time.monotonic() - started

    def _estimate(self, now_ns: int) -> bool:
        groups, arrivals = self._window()
        if len(groups) < 2:
            return False
        # the first estimate finds the world (the floor, by default); later ones are solved
        # in the reference camera's frame and placed in the world the calibration already has
        reference = self.calibration.cameras.get(self.calibration.reference)
        params = dataclasses.replace(
            self.params,
            require_all=False,
            reference=self.calibration.reference or self.params.reference,
            world=self.params.world if reference is None else "camera",
        )
        calibrator = Calibrator(params)
        try:
            # the arrival times are this node's own receiving clock
            estimate = calibrator.calibrate(
                groups, arrival_ns=arrivals, one_receiver=True, known_poses=self._known
            )
        except CalibrationError as exc:
            self.drops["estimate_failed"] += 1
            self._event(now_ns, f"estimate failed: {exc}")
            return False
        if reference is not None and self._known is None:  # known poses come placed
            place_in_world(estimate, reference.extrinsics)
        self.drops.update(calibrator.drops)
        changed = False
        if not self.calibration.reference:
            self.calibration.reference = estimate.reference
        tracks = self._tracks(groups)  # for judging disagreeing estimates, then the baseline
        for camera, new in estimate.cameras.items():
            first = groups[camera][0].stamp_ns
            changed |= self._merge(camera, new, first, tracks=tracks, now_ns=now_ns)
        for camera, reason in (calibrator.result.refused if calibrator.result else {}).items():
            self._event(now_ns, f"{camera}: not calibrated yet ({reason})")
        self._baseline = {pair: distance for pair, (distance, _) in self._residuals(tracks).items()}
        return changed

    def _merge(
        self,
        camera: str,
        new: CameraCalibration,
        first: int,
        *,
        tracks: dict[str, list[BodyTrack]],
        now_ns: int,
    ) -> bool:
        """Take a camera's new estimate or not; True if taken.

        ``first`` is the stamp of the camera's first frame the estimate rests on, ``tracks``
        the body tracks of the frames it was made from.
        """
        old = self.calibration.cameras.get(camera)
        if new.flagged:
            # a doubtful estimate is never used: the last good calibration (or none) stays
            self.drops["estimate_flagged"] += 1
            kept = "keeping the last good calibration" if old is not None else "not calibrated"
            self._event(now_ns, f"{camera}: estimate flagged ({new.flagged}); {kept}")
            return False
        # while the window still holds every frame the current estimate rests on (it is
        # refilling after a start or a recalibration) the new estimate, on more of the same
        # data, supersedes it; once frames slide out, or for a pose loaded from a file, an
        # agreeing estimate is blended in and a disagreeing one must be confirmed
        grown = camera in self._support and first <= self._support[camera]
        if old is None or camera in self._changed:
            self._changed.discard(camera)
            self._event(now_ns, f"{camera}: calibrated", "calibrated")
        elif _agrees(old, new):
            if not grown:
                new = _blend(old, new, self.params.blend)
        elif not self._replaces(camera, old, new, grown=grown, tracks=tracks, now_ns=now_ns):
            self.drops["estimate_disagrees"] += 1
            return False
        self._rivals.pop(camera, None)
        self.calibration.cameras[camera] = new
        self._support[camera] = first
        return True

    def _replaces(
        self,
        camera: str,
        old: CameraCalibration,
        new: CameraCalibration,
        *,
        grown: bool,
        tracks: dict[str, list[BodyTrack]],
        now_ns: int,
    ) -> bool:
        """Whether a disagreeing estimate replaces the current pose (with an event if so)."""
        fit = "" if grown else self._outvoted(camera, new) and self._better_fit(camera, new, tracks)
        if not (grown or fit):
            return False
        who = (
            "an estimate on more of the same frames"
            if grown
            else f"{REPLACE_AFTER} estimates in a row"
        )
        clock, angle, distance = _difference(old, new)
        self._event(
            now_ns,
            f"{camera}: replaced, {who} disagreed with it by {angle:.1f} deg, "
            f"{100 * distance:.0f} cm, {1e3 * clock:.0f} ms{fit}",
            "replaced",
        )
        return True

    def _better_fit(
        self, camera: str, new: CameraCalibration, tracks: dict[str, list[BodyTrack]]
    ) -> str:
        """Why ``new`` should replace the camera's pose, or "" if it should not.

        It should when its camera's pairs fit ``tracks`` (of the frames it came from) clearly
        better than with the current pose: ``REPLACE_MARGIN`` lower median joint distance.
        """
        trial = dataclasses.replace(
            self.calibration, cameras={**self.calibration.cameras, camera: new}
        )
        before = self._residuals(tracks, camera=camera)
        after = self._residuals(tracks, trial, camera=camera)
        pairs = before.keys() & after.keys()
        if not pairs:
            return ""
        old_fit = float(np.median([before[p][0] for p in pairs]))
        new_fit = float(np.median([after[p][0] for p in pairs]))
        if new_fit >= (1.0 - REPLACE_MARGIN) * old_fit:
            return ""
        return (
            f" and fit their frames better (median joint distance {100 * old_fit:.1f} -> "
            f"{100 * new_fit:.1f} cm)"
        )

    def _outvoted(self, camera: str, new: CameraCalibration) -> bool:
        """Whether ``new`` makes ``REPLACE_AFTER`` disagreeing estimates that agree in a row."""
        rivals = self._rivals.setdefault(camera, [])
        if rivals and not _agrees(rivals[-1], new):
            rivals.clear()
        rivals.append(new)
        return len(rivals) >= REPLACE_AFTER

    def check(self, now_ns: int) -> bool:
        """Look for moved cameras or jumped clocks in the newest frames; True if one is found."""
        groups, _ = self._window(CHECK_LENGTH)
        params = self.params
        residuals = self._residuals(self._tracks(groups))
        suspicious = {
            pair
            for pair, (distance, shift) in residuals.items()
            if shift > params.moved_shift
            or (
                distance > params.moved_floor
                and distance > MOVED_RATIO * self._baseline.get(pair, distance)
            )
        }
        flagged = set()
        for camera in self.calibration.cameras:
            mine = [pair for pair in residuals if camera in pair]
            if mine and all(pair in suspicious for pair in mine):
                flagged.add(camera)
        reference = self.calibration.reference
        if reference in flagged or (flagged and len(self.calibration.cameras) == 2):
            # with two cameras, or when the reference itself moved, the others are redone
            flagged = {c for c in self.calibration.cameras if c != reference}
        flagged -= self._changed
        if not flagged:
            return False
        with self._lock:
            for camera in flagged:
                frames = self._frames.get(camera)
                if frames:
                    self._since[camera] = frames[-1][0].stamp_ns - round(CHECK_LENGTH * 1e9)
                self._changed.add(camera)
                self._changed_at[camera] = now_ns
        for camera in sorted(flagged):
            self.calibration.cameras[camera].quality["status"] = "recalibrating"
            self._event(now_ns, f"{camera}: moved or clock jumped, recalibrating", "moved")
        return True

    def _tracks(self, groups: dict[str, list]) -> dict[str, list[BodyTrack]]:
        """Per camera the body tracks of these frames, as the check compares them."""
        return {
            c: extract_tracks(frames, c, max_gap=self.params.max_gap, min_frames=5)
            for c, frames in groups.items()
        }

    def _residuals(
        self,
        tracks: dict[str, list[BodyTrack]],
        calibration: Calibration | None = None,
        camera: str | None = None,
    ) -> dict[tuple[str, str], tuple[float, float]]:
        """Per calibrated camera pair in these tracks: median joint distance and displacement (m).

        The displacement is the length of the per-axis median of the residual vectors: the
        SDKs' noise scatters them, a moved camera shifts them all the same way. With the
        current calibration unless another is given; only the pairs of ``camera`` if given.
        """
        cal = calibration or self.calibration
        cameras = [c for c in tracks if c in cal.cameras and c not in self._changed]
        params = self.params
        out = {}
        for k, a in enumerate(cameras):
            for b in cameras[k + 1 :]:
                if camera is not None and camera not in (a, b):
                    continue
                relative = cal.cameras[a].extrinsics.inverse() @ cal.cameras[b].extrinsics
                clocks = _clock(a, cal.cameras[a]), _clock(b, cal.cameras[b])
                vectors = _matched_residuals((tracks[a], tracks[b]), clocks, relative, params)
                if len(vectors):
                    out[a, b] = (
                        float(np.median(np.linalg.norm(vectors, axis=1))),
                        float(np.linalg.norm(np.median(vectors, axis=0))),
                    )
        return out

    def _event(self, at_ns: int, message: str, kind: str = "") -> None:
        with self._events_lock:
            self.events.append((at_ns, message))
            self.event_count += 1
            if kind:
                self.tally[kind] += 1

    def events_since(self, count: int) -> tuple[list[tuple[int, str]], int]:
        """The events after the first ``count`` that are still kept, and ``event_count``."""
        with self._events_lock:
            new = min(self.event_count - count, len(self.events))
            return list(self.events)[len(self.events) - new :], self.event_count

    def diagnostics(self) -> dict[str, str]:
        """Estimates run, the last one's duration, and the events by kind (``tally``)."""
        return {
            "estimates": str(self.estimates),
            "estimate_s": f"{self.estimate_seconds:.2f}",
            **{f"events.{kind}": str(n) for kind, n in sorted(self.tally.items())},
        }

    def snapshot(self) -> dict[str, Any]:
        """Counts for diagnostics: frames buffered per camera, cameras waiting or silent, drops."""
        with self._lock:
            buffered = {c: len(f) for c, f in self._frames.items()}
        return {
            "buffered": buffered,
            "recalibrating": sorted(self._changed),
            "silent": sorted(self._silent),
            **self.drops,
        }


_MIN_CHECK_OVERLAP = 1.0
"""Seconds two tracks must be seen together to be compared by the check."""


def _matched_residuals(
    tracks: tuple[list[BodyTrack], list[BodyTrack]],
    clocks: tuple[CameraClock, CameraClock],
    relative: RigidTransform,
    params: LiveCalibratorParams,
) -> np.ndarray:
    """``(N, 3)`` residual vectors of the body pairs that the current calibration puts together.

    Every track of a is paired with at most one track of b at a time, nearest pairs first
    (median distance). With the poses known, where people stand tells them apart; their poses'
    shapes over a few seconds do not always (two people walking alike were matched wrongly,
    and the 2 m residual flagged a camera that had not moved). A camera that did move still
    shows: its nearest pairs are far too.
    """
    candidates = []
    for i, track_a in enumerate(tracks[0]):
        for j, track_b in enumerate(tracks[1]):
            c = pair_correspondences(track_a, track_b, *clocks, params)
            if c is None or np.ptp(c.times) < _MIN_CHECK_OVERLAP:
                continue
            vectors = _invariant_residuals(c, relative)
            if len(vectors):
                distance = float(np.median(np.linalg.norm(vectors, axis=1)))
                span = (float(c.times[0]), float(c.times[-1]))
                candidates.append((distance, i, j, span, vectors))
    candidates.sort(key=lambda candidate: candidate[0])
    taken: dict[tuple[int, int], list[tuple[float, float]]] = {}  # (side, track) -> spans
    matched = []
    for _, i, j, (start, end), vectors in candidates:
        # a track may pair with several of the other camera's over disjoint spans (the SDK
        # gave the person a new id), never with two at once
        spans = taken.get((0, i), []) + taken.get((1, j), [])
        if any(s < end and start < e for s, e in spans):
            continue
        taken.setdefault((0, i), []).append((start, end))
        taken.setdefault((1, j), []).append((start, end))
        matched.append(vectors)
    return np.concatenate(matched) if matched else np.zeros((0, 3))


def _invariant_residuals(c: Correspondences, relative: RigidTransform) -> np.ndarray:
    """Residual vectors (camera a frame) of the mirror-proof points under a pose.

    The midline joints and the midpoints of left/right pairs do not change when an SDK swaps
    left and right, so its mistakes do not flag a camera.
    """
    keep = np.flatnonzero(np.arange(len(c.mirror)) <= c.mirror)
    partner = c.mirror[keep]
    points_a = 0.5 * (c.points_a[:, keep] + c.points_a[:, partner])
    points_b = 0.5 * (c.points_b[:, keep] + c.points_b[:, partner])
    valid = np.minimum(c.weights[:, keep], c.weights[:, partner]) > 0
    return (relative.apply(points_b) - points_a)[valid]
