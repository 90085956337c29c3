"""Offline spatio-temporal calibration: per-camera skeleton streams in, a Calibration out.

:class:`Calibrator` chains the steps of this package: body tracks per camera
(:mod:`~hiros_calib.tracks`), clock offsets and drift (:mod:`~hiros_calib.sync`), then camera
poses (:mod:`~hiros_calib.extrinsics`), then the offsets refined by the joints' motion under
those poses (:mod:`~hiros_calib.retime`), and writes the result as the DESIGN.md calibration
with quality figures per camera. The live version is :class:`hiros_calib.live.LiveCalibrator`.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from hiros_calib.extrinsics import (
    CameraPose,
    Correspondences,
    ExtrinsicsParams,
    PairPose,
    associate,
    estimate_pair_pose,
    motion_lever,
    pair_correspondences,
    solve_poses,
)
from hiros_calib.known import (
    check_lags,
    keep_known_poses,
    known_relative_poses,
    pair_pose,
    place_as_known,
)
from hiros_calib.lags import settle_lag, split_half_spread
from hiros_calib.quality import arrival_offsets_from_delays, flag_cameras
from hiros_calib.retime import retime
from hiros_calib.sync import (
    CameraClock,
    PairOffset,
    Settle,
    SyncParams,
    synchronise,
)
from hiros_calib.sync.params import MIN_LAG_MARGIN
from hiros_calib.tracks import BodyTrack, extract_tracks
from hiros_calib.world import align_to_floor, fit_floor
from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.errors import CalibrationError, ConfigError
from hiros_core.geometry import RigidTransform
from hiros_core.model import SkeletonGroup

__all__ = ["CalibrationResult", "Calibrator", "CalibratorParams"]

WORLDS = ("floor", "camera")
"""The world frames a calibration can be given in (``CalibratorParams.world``)."""

MIN_TRACK_FRAMES = 10
"""Body tracks with fewer frames are left out (a glimpse pins neither a lag nor a pose)."""

Progress = Callable[[str, float], None]
"""Called with a stage description and the fraction (0..1) of the work done."""


@dataclass
class CalibratorParams(SyncParams, ExtrinsicsParams):
    """Every calibration parameter (ROS parameter names and defaults of the ``calib`` node).

    The time-offset fields come from :class:`~hiros_calib.sync.SyncParams`, the pose fields
    from :class:`~hiros_calib.extrinsics.ExtrinsicsParams`; ``joints`` serves both.
    """

    reference: str = ""
    """Reference camera (the clock and the poses are relative to it; its view gives the world x
    axis); empty: the first camera by name."""
    world_frame: str = "world"
    """Name of the world frame written to the calibration file."""
    world: str = "floor"
    """``floor``: z up and the floor at z = 0, found from the people (REP-103; x along the
    reference camera's view); ``camera``: the reference camera's own frame."""
    max_gap: float = 0.25
    """A body id unseen for longer than this (s) starts a new track."""
    min_confidence: float = 0.5
    """Joints below this fraction of the driver's confidence scale are left out."""
    require_all: bool = True
    """Raise CalibrationError when any camera cannot be calibrated (else leave it out)."""


@dataclass
class CalibrationResult:
    """Everything a calibration run found, for reports and plots."""

    calibration: Calibration
    clocks: dict[str, CameraClock]
    sync_pairs: list[PairOffset]
    poses: dict[str, CameraPose]
    pose_pairs: list[PairPose]
    tracks: dict[str, list[BodyTrack]]
    refused: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    """What the calibration decided about its input (e.g. log times that carry no clock)."""


class Calibrator:
    """Clock offsets, drift and poses of N cameras from the people they all watch.

    Feed frames with :meth:`update` (or pass them to :meth:`calibrate`); inputs are per-camera
    SkeletonGroups in the camera frame and on the camera clock. Drop reasons are counted in
    ``drops``.
    """

    def __init__(self, params: CalibratorParams | None = None) -> None:
        self.params = params or CalibratorParams()
        if self.params.world not in WORLDS:
            msg = f"world must be one of {', '.join(WORLDS)}, not {self.params.world!r}"
            raise ConfigError(msg)
        self.drops: Counter[str] = Counter()
        self.result: CalibrationResult | None = None
        self._groups: dict[str, list[SkeletonGroup]] = defaultdict(list)
        self._arrivals: dict[str, list[int]] = defaultdict(list)

    def update(self, group: SkeletonGroup, arrival_ns: int | None = None) -> SkeletonGroup:
        """Keep a camera frame for the next :meth:`calibrate`; returns it unchanged.

        ``arrival_ns`` is when the frame reached the receiver (recording log time or the
        node's clock); with it the clock search is narrowed (see ``prior_window``).
        """
        if not group.frame_id:
            self.drops["no_frame_id"] += 1
            return group
        self._groups[group.camera].append(group)
        if arrival_ns is not None:
            self._arrivals[group.camera].append(arrival_ns - group.stamp_ns)
        return group

    def calibrate(
        self,
        camera_groups: Mapping[str, Sequence[SkeletonGroup]] | None = None,
        progress: Progress | None = None,
        arrival_ns: Mapping[str, Sequence[int]] | None = None,
        *,
        one_receiver: bool = False,
        known_poses: Calibration | None = None,
    ) -> Calibration:
        """The calibration of every camera; also kept with all details in ``self.result``.

        Args:
            camera_groups: per camera its frames; default: those given to :meth:`update`.
            progress: optional progress callback.
            arrival_ns: per camera, when each of its frames (same order) reached the
                receiver; default: those given to :meth:`update`, if any.
                They narrow each clock search to the lag they suggest; without them every
                lag is searched, and a pair whose people repeat one motion (another lag
                correlating nearly as well) is refused as ambiguous rather than guessed.
            one_receiver: the arrival times are the caller's own receiving clock (a live
                node), never each camera's host clock, so they are used even when they look
                alike on every camera (cameras whose clocks already agree).
            known_poses: an earlier calibration of the same cameras, unmoved (people walking
                across the area pin poses down; people exercising on one spot do not): its
                poses and world are kept, and only the clocks are found, the skeletons judging
                each lag against the known poses. Each camera's quality says how well the
                known pose still fits (``known_pose_*``); a camera it no longer fits is flagged
                as moved.

        Raises:
            CalibrationError: fewer than two cameras, or (with ``require_all``) a camera
                whose clock or pose the data cannot determine, with the reason (a camera
                ``known_poses`` lacks among them).

        """
        groups = dict(camera_groups) if camera_groups is not None else dict(self._groups)
        if camera_groups is None:
            delays = {c: d for c, d in self._arrivals.items() if d}
        else:
            delays = {
                c: [int(a) - g.stamp_ns for a, g in zip(arrival_ns[c], groups[c], strict=False)]
                for c in groups
                if arrival_ns and c in arrival_ns
            }
        arrival_offsets, arrival_notes = arrival_offsets_from_delays(
            delays, one_receiver=one_receiver
        )
        notes = list(arrival_notes)
        report = progress or (lambda _stage, _done: None)
        params = self.params
        if len(groups) < 2:
            msg = f"calibration needs at least two cameras, got {sorted(groups)}"
            raise CalibrationError(msg)
        reference = params.reference or min(groups)
        if reference not in groups:
            msg = f"reference camera {reference!r} is not among the cameras {sorted(groups)}"
            raise CalibrationError(msg)
        cameras = [reference, *[c for c in groups if c != reference]]
        known = (
            known_relative_poses(known_poses, cameras, reference)
            if known_poses is not None
            else None
        )
        report("body tracks", 0.0)
        tracks = {
            camera: extract_tracks(
                groups[camera],
                camera,
                max_gap=params.max_gap,
                min_frames=MIN_TRACK_FRAMES,
                min_confidence=params.min_confidence,
                drops=self.drops,
            )
            for camera in cameras
        }
        report("clock offsets", 0.1)
        clocks, sync_pairs = synchronise(
            tracks, reference, params, arrival_offsets, settle=self._settle(tracks, known)
        )
        if known is not None:
            check_lags(sync_pairs, tracks, known)
        refused = {c: clock.reason for c, clock in clocks.items() if not clock.ok}
        self._check(refused, "clock")
        report("camera poses", 0.6)
        pose_pairs = self._pose_pairs(cameras, tracks, clocks)
        calibrated = [c for c in cameras if clocks[c].ok]
        poses = (
            keep_known_poses(calibrated, known, pose_pairs)
            if known is not None
            else solve_poses(calibrated, reference, pose_pairs)
        )
        refused.update({c: pose.reason for c, pose in poses.items() if not pose.ok})
        self._check(refused, "pose")
        report("clocks by the motion", 0.9)
        clocks, motion_shifts = retime(
            clocks,
            reference,
            sync_pairs=sync_pairs,
            pose_pairs=pose_pairs,
            poses=poses,
            tracks=tracks,
            params=params,
        )
        calibration = _to_calibration(reference, params.world_frame, groups, clocks, poses)
        calibration.cameras = {
            c: calibration.cameras[c] for c in cameras if c in calibration.cameras
        }
        for camera, cal in calibration.cameras.items():
            cal.quality.update(_sync_quality(camera, sync_pairs))
        if arrival_offsets or arrival_notes:
            for cal in calibration.cameras.values():
                cal.quality["arrival_times"] = "ignored" if arrival_notes else "used"
        flag_cameras(
            calibration,
            sync_pairs,
            pose_pairs,
            motion_shifts=motion_shifts,
            poses_known=known is not None,
        )
        if known_poses is not None:
            place_as_known(calibration, known_poses)
        elif params.world == "floor":
            notes.extend(_align_to_floor(calibration, tracks))
        self.result = CalibrationResult(
            calibration, clocks, sync_pairs, poses, pose_pairs, tracks, refused, notes
        )
        report("done", 1.0)
        return calibration

    def _settle(
        self, tracks: dict[str, list[BodyTrack]], known: dict[str, RigidTransform] | None
    ) -> Settle:
        """The poses' check of each pair's lag (see :mod:`~hiros_calib.lags`)."""
        params = self.params

        def settle(pair: PairOffset, repin: Callable[[float], PairOffset]) -> PairOffset:
            return settle_lag(
                pair,
                tracks[pair.camera_a],
                tracks[pair.camera_b],
                params,
                repin,
                max_ambiguity=params.max_ambiguity,
                min_lag_margin=MIN_LAG_MARGIN,
                known=(
                    pair_pose(known, pair.camera_a, pair.camera_b) if known is not None else None
                ),
            )

        return settle

    def _check(self, refused: dict[str, str], what: str) -> None:
        if refused and self.params.require_all:
            camera, reason = next(iter(refused.items()))
            msg = f"cannot determine the {what} of camera {camera}: {reason}"
            raise CalibrationError(msg)

    def _pose_pairs(
        self,
        cameras: list[str],
        tracks: dict[str, list[BodyTrack]],
        clocks: dict[str, CameraClock],
    ) -> list[PairPose]:
        params = self.params
        pairs = []
        for k, a in enumerate(cameras):
            for b in cameras[k + 1 :]:
                if not (clocks[a].ok and clocks[b].ok):
                    continue
                matches = associate(tracks[a], tracks[b], clocks[a], clocks[b], params)
                found = [
                    pair_correspondences(tracks[a][i], tracks[b][j], clocks[a], clocks[b], params)
                    for i, j, _ in matches
                ]
                usable = [c for c in found if c is not None]
                joined = Correspondences.concatenate(usable) if usable else None
                pose = estimate_pair_pose(joined, camera_a=a, camera_b=b)
                pose.quality["bodies_associated"] = len(matches)
                pose.body_pairs = [(i, j) for i, j, _ in matches]
                pose.reported = joined
                lever = motion_lever(pose.correspondences)  # None for a refused pair
                if lever is not None:
                    pose.quality["motion_lever_m"] = round(lever, 3)
                spread = split_half_spread(joined) if pose.ok else None
                if spread is not None:
                    pose.quality["split_half_deg"] = round(spread[0], 3)
                    pose.quality["split_half_cm"] = round(100 * spread[1], 2)
                pairs.append(pose)
        return pairs


def _align_to_floor(calibration: Calibration, tracks: dict[str, list[BodyTrack]]) -> list[str]:
    """Move the calibration into the floor's world; a note when no floor could be found."""
    poses = {name: cam.extrinsics for name, cam in calibration.cameras.items()}
    floor = fit_floor(tracks, poses)
    if floor is None:
        return [
            "no floor found (no one was seen with resting feet and a body vertical): the world "
            "is the reference camera's frame"
        ]
    align_to_floor(calibration, floor)
    return []


def _to_calibration(
    reference: str,
    world_frame: str,
    groups: Mapping[str, Sequence[SkeletonGroup]],
    clocks: dict[str, CameraClock],
    poses: dict[str, CameraPose],
) -> Calibration:
    calibration = Calibration(reference=reference, world_frame=world_frame)
    for camera, pose in poses.items():
        clock = clocks[camera]
        if not (pose.ok and clock.ok):
            continue
        frame_id = next((g.frame_id for g in groups[camera] if g.frame_id), camera)
        quality: dict[str, Any] = {f"time_{k}": v for k, v in clock.quality.items()}
        quality.update(pose.quality)
        calibration.cameras[camera] = CameraCalibration(
            frame_id=frame_id,
            time_offset=clock.time_offset,
            drift=clock.drift,
            drift_epoch=clock.drift_epoch,
            translation=pose.transform.translation,
            rotation=pose.transform.quaternion,
            quality=quality,
        )
    return calibration


def _sync_quality(camera: str, pairs: list[PairOffset]) -> dict[str, Any]:
    """Correlation figures of the camera's usable pairs (the best pair's, and the counts)."""
    mine = [p for p in pairs if p.ok and camera in (p.camera_a, p.camera_b)]
    if not mine:
        return {}
    best = max(mine, key=lambda p: p.quality.get("refined_correlation", 0.0))
    out = {
        f"time_{key}": best.quality[key]
        for key in ("peak", "sharpness", "refined_correlation")
        if key in best.quality
    }
    out["time_pairs_used"] = sum(p.quality.get("pairs_used", 0) for p in mine)
    return out
