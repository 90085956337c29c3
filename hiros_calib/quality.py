"""Whether a calibration's input and result can be trusted: arrival times and loop checks.

Two questions a calibration must answer before anyone uses it:

- **Do the recording's log times say anything about the clocks?** They do when every frame
  was logged on one receiver's clock: ``log - stamp`` then differs between cameras by their
  clock offsets. When each camera has its own recording host, each frame is logged on its own
  camera's clock, ``log - stamp`` is just the host's latency on every camera, and the lag
  those log times suggest (about 0) says nothing. Log times are then ignored, and so they are
  when the motion contradicts them (:mod:`~hiros_calib.sync`).
- **Is the result consistent?** Every camera pair measures a clock lag and a pose of its
  own; the solved clocks and poses must reproduce each of them (loops close), and each pair's
  lag must fit the skeletons better than the runner-up lag (:mod:`~hiros_calib.lags`), and
  each pair's pose must come out alike from two halves of the recording (alternating blocks
  of time; half their spread estimates the pose's error). A camera that fails is *flagged*
  with the reason: written, but never used silently.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from hiros_calib.extrinsics import PairPose, relative_error
from hiros_calib.known import KNOWN_POSE_BEST_LAG, KNOWN_POSE_RESIDUAL, OWN_POSE_RESIDUAL
from hiros_calib.retime import SHIFT_SE_INFLATION, MotionShift
from hiros_calib.sync import PairOffset
from hiros_core.calibration import Calibration, CameraCalibration

_Pair = TypeVar("_Pair", PairOffset, PairPose)

__all__ = ["ON_ONE_SPOT", "LoopTolerances", "arrival_offsets_from_delays", "flag_cameras"]

ON_ONE_SPOT = "the people stayed on one spot"
"""Part of a camera's flag when its pose rests on joints that barely moved about where the
people stood, so that nothing in the recording pins the rotation down against the body
tracker's own errors."""

OWN_CLOCK_LATENCY = 0.5
"""Largest ``log - stamp`` (s) of a host logging its own camera's frames: its latency, tens
of milliseconds, never negative."""
OWN_CLOCK_SPREAD = 0.15
"""Largest difference (s) between the cameras' ``log - stamp`` for log times to be taken as
each camera's own clock. On one receiver's clock they differ by the cameras' clock offsets;
where those are this small, the lag the log times suggest is within the spread anyway."""


@dataclass
class LoopTolerances:
    """How far solved clocks and poses may miss a pair's own measurement before flagging."""

    time_s: float = 0.05
    rotation_deg: float = 2.0
    translation_m: float = 0.10
    uncertainty_deg: float = 1.5
    """Largest pose uncertainty, degrees: half the split-half spread of a pair's pose, and
    the whole split-half spread of a camera's final pose (its error is mostly a bias the
    halves share, about twice their half spread on the simulator's noisier SDK)."""
    uncertainty_m: float = 0.075
    """Largest pose uncertainty in translation, metres (same two figures)."""
    min_motion_lever_m: float = 0.38
    """Least RMS distance (m) the joints must move about their own means on at least one of
    a camera's pairs (:func:`~hiros_calib.extrinsics.motion_lever`): people exercising or
    gesturing on one spot move less, people walking, even to and fro along one line, more
    (docs/calibration-robustness.md, session 20)."""
    known_pose_excess_m: float = 0.015
    """Most (m) by which the same-instant joints may lie further apart under poses given
    beforehand than under a pose fitted to the recording alone (:mod:`hiros_calib.known`)
    before the camera is taken to have moved: 0.0-0.7 cm on cameras left in place, 1.6-2.4
    cm on one turned by 2 deg (docs/calibration-robustness.md, session 26)."""
    known_lag_s: float = 0.1
    """Most (s) a pair's lag may lie from the one at which poses given beforehand fit its
    skeletons best (``known_pose_best_lag``; two steps of that search's grid)."""
    motion_confirms_s: float = 0.01
    """A pair's lag the clocks miss is set aside, not flagged, when the joints' motion puts
    that pair within this (s) of the clocks, twice its own standard error included
    (:mod:`~hiros_calib.retime`): the clocks are right there, the pair's correlation is not."""


def arrival_offsets_from_delays(
    delays: Mapping[str, Sequence[int]], *, one_receiver: bool = False
) -> tuple[dict[str, float], list[str]]:
    """Per camera the typical ``log - stamp`` (s), or none with the reason why.

    ``delays`` holds per camera each frame's ``log time - stamp`` (ns). Log times that look
    like each camera's own clock (``log - stamp`` a latency on every camera: between 0 and
    :data:`OWN_CLOCK_LATENCY`, and alike within :data:`OWN_CLOCK_SPREAD`) are no information
    about the lag: an empty mapping and a note are returned. Cameras whose clocks already
    agree look the same through one receiver, so a caller that received the frames itself
    (the live calibrator: ``one_receiver``) keeps them.
    """
    typical = {c: float(np.median(d)) * 1e-9 for c, d in delays.items() if len(d)}
    if len(typical) < 2 or one_receiver:
        return typical, []
    values = list(typical.values())
    latencies = all(-0.005 <= v < OWN_CLOCK_LATENCY for v in values)
    if latencies and max(values) - min(values) < OWN_CLOCK_SPREAD:
        shown = ", ".join(f"{c} {1e3 * v:+.0f} ms" for c, v in sorted(typical.items()))
        note = (
            f"the log times look like each camera's own clock (log - stamp: {shown}), as when "
            "each camera has its own recording host: they say nothing about the clock offsets "
            "and are ignored"
        )
        return {}, [note]
    return typical, []


def flag_cameras(
    calibration: Calibration,
    sync_pairs: Sequence[PairOffset],
    pose_pairs: Sequence[PairPose],
    tolerances: LoopTolerances | None = None,
    motion_shifts: Sequence[MotionShift] = (),
    *,
    poses_known: bool = False,
) -> None:
    """Add loop-closure figures to every camera's quality; flag those that fail a check.

    A camera is flagged when one of its pairs' lag is contradicted by the poses, or when the
    solved clocks or poses miss one of its pairs' own measurements by more than the
    tolerances (with three or more cameras: a loop that does not close), unless the joints'
    motion (``motion_shifts``, measured at the solved clocks) confirms the clocks for that
    pair. The reference camera is never flagged on its own: it defines the frame and the
    clock. With ``poses_known`` (poses kept from an earlier calibration, not solved here) the
    poses are checked only for whether they still fit the recording.
    """
    tolerances = tolerances or LoopTolerances()
    cameras = calibration.cameras
    reasons: dict[str, list[str]] = {name: [] for name in cameras}
    confirmed = _confirmed_by_motion(motion_shifts, tolerances)
    _check_clocks(cameras, sync_pairs, tolerances, reasons, confirmed)
    if poses_known:
        _check_known_lags(cameras, sync_pairs, tolerances, reasons)
        _check_known_poses(cameras, pose_pairs, tolerances, reasons)
    else:
        _check_poses(cameras, pose_pairs, tolerances, reasons)
    for name, found in reasons.items():
        if found and name != calibration.reference:
            cameras[name].flagged = "; ".join(dict.fromkeys(found))


def _confirmed_by_motion(
    shifts: Sequence[MotionShift], tolerances: LoopTolerances
) -> dict[frozenset[str], float]:
    """Camera pairs whose motion agrees with the solved clocks, and by how much (s)."""
    return {
        frozenset((s.camera_a, s.camera_b)): s.shift
        for s in shifts
        if abs(s.shift) + SHIFT_SE_INFLATION * s.standard_error <= tolerances.motion_confirms_s
    }


def _check_clocks(
    cameras: dict[str, CameraCalibration],
    sync_pairs: Sequence[PairOffset],
    tolerances: LoopTolerances,
    reasons: dict[str, list[str]],
    confirmed: dict[frozenset[str], float],
) -> None:
    """Each pair's lag against the solved clocks, and the poses' verdict on it."""
    for pair in sync_pairs:
        if not (pair.ok and pair.camera_a in cameras and pair.camera_b in cameras):
            continue
        _lag_figures(cameras, pair)
        if pair.quality.get("flagged"):
            _blame_both(reasons, pair, str(pair.quality["flagged"]))
        miss = _clock_miss(cameras[pair.camera_a], cameras[pair.camera_b], pair)
        _keep_largest(cameras, pair, "loop_time_ms", round(1e3 * abs(miss), 2))
        agrees = confirmed.get(frozenset((pair.camera_a, pair.camera_b)))
        if abs(miss) > tolerances.time_s and agrees is not None:
            note = (
                f"{pair.camera_a}-{pair.camera_b} {1e3 * miss:+.0f} ms (motion {1e3 * agrees:+.1f})"
            )
            for name in (pair.camera_a, pair.camera_b):
                cameras[name].quality["time_lag_set_aside"] = note
        elif abs(miss) > tolerances.time_s:
            text = (
                f"the clocks miss the {pair.camera_a}-{pair.camera_b} lag by {1e3 * miss:+.0f} "
                f"ms (a loop of camera clocks does not close; tolerance "
                f"{1e3 * tolerances.time_s:.0f} ms)"
            )
            _blame_both(reasons, pair, text)
    _check_unconfirmed_choices(cameras, sync_pairs, reasons)


def _check_unconfirmed_choices(
    cameras: dict[str, CameraCalibration],
    sync_pairs: Sequence[PairOffset],
    reasons: dict[str, list[str]],
) -> None:
    """A reason for a camera whose clock rests on one lag the skeletons chose among alike lags.

    Where the motion repeats, the skeletons pick the lag among its repetitions, and they can
    fit a wrong repetition better than the true lag (a camera seeing the same side of the
    people at the wrong repetition as the other camera does at the true one). A second pair,
    closing a loop, confirms the choice; a camera linked by that one pair alone is doubtful.
    """
    usable, links = _usable_links(sync_pairs, cameras)
    for pair in usable:
        if not _chosen_by_skeletons(pair):
            continue
        text = (
            f"the {pair.camera_a}-{pair.camera_b} lag {pair.offset:+.3f} s was chosen by the "
            "skeletons among lags the motion supports alike (runner-up "
            f"{pair.quality.get('lag_fit_runner_up_lag', '?')} s, fit margin "
            f"{pair.quality.get('lag_fit_margin', '?')}x), and no other camera pair confirms it"
        )
        for name in (pair.camera_a, pair.camera_b):
            if links[name] == 1:
                reasons[name].append(text)


def _blame_both(reasons: dict[str, list[str]], pair: PairOffset | PairPose, text: str) -> None:
    """The same reason for both cameras of a pair."""
    for name in (pair.camera_a, pair.camera_b):
        reasons[name].append(text)


def _usable_links(
    pairs: Sequence[_Pair], cameras: dict[str, CameraCalibration]
) -> tuple[list[_Pair], Counter[str]]:
    """The pairs that hold (``ok``, both cameras calibrated) and how many link each camera."""
    usable = [p for p in pairs if p.ok and p.camera_a in cameras and p.camera_b in cameras]
    return usable, Counter(name for p in usable for name in (p.camera_a, p.camera_b))


def _chosen_by_skeletons(pair: PairOffset) -> bool:
    """Whether the pair's lag is the skeletons' choice among alike lags (not the log times')."""
    prior_used = str(pair.quality.get("arrival_prior", "")).startswith("used")
    return pair.quality.get("lag_decided_by") == "poses" and not prior_used


def _check_poses(
    cameras: dict[str, CameraCalibration],
    pose_pairs: Sequence[PairPose],
    tolerances: LoopTolerances,
    reasons: dict[str, list[str]],
) -> None:
    """Each pair's pose against the solved poses, and how well the data pin both down."""
    usable, links = _usable_links(pose_pairs, cameras)
    for pose in usable:
        solved = cameras[pose.camera_a].extrinsics.inverse() @ cameras[pose.camera_b].extrinsics
        angle, distance = relative_error(pose.transform, solved)
        _keep_largest(cameras, pose, "loop_rotation_deg", round(angle, 3))
        _keep_largest(cameras, pose, "loop_translation_cm", round(100 * distance, 2))
        if "motion_lever_m" in pose.quality:
            _keep_largest(cameras, pose, "motion_lever_m", pose.quality["motion_lever_m"])
        _uncertainty(cameras, pose, tolerances, reasons, links)
        if angle > tolerances.rotation_deg or distance > tolerances.translation_m:
            text = (
                f"the poses miss the {pose.camera_a}-{pose.camera_b} pair's own pose by "
                f"{angle:.1f} deg and {100 * distance:.1f} cm (a loop of camera poses does not "
                "close)"
            )
            _blame_both(reasons, pose, text)
    for name, camera in cameras.items():
        _resting_on_one_spot(name, camera, tolerances, reasons[name])
        _final_pose_spread(name, camera, tolerances, reasons[name])
        if not reasons[name]:
            _combined_rotation(name, camera, tolerances, reasons[name], one_pair=links[name] <= 1)


def _check_known_lags(
    cameras: dict[str, CameraCalibration],
    sync_pairs: Sequence[PairOffset],
    tolerances: LoopTolerances,
    reasons: dict[str, list[str]],
) -> None:
    """A reason where the known poses fit a pair's skeletons best at another lag than its own."""
    usable, _ = _usable_links(sync_pairs, cameras)
    for pair in usable:
        best = pair.quality.get(KNOWN_POSE_BEST_LAG)
        if best is None or abs(best - pair.offset) <= tolerances.known_lag_s:
            continue
        text = (
            f"the known poses fit the {pair.camera_a}-{pair.camera_b} skeletons best at lag "
            f"{best:+.2f} s, not at the lag the motion gives ({pair.offset:+.3f} s): the motion "
            "repeats too alike to time this recording (record a stretch of varied motion, or "
            "give --max-offset)"
        )
        _blame_both(reasons, pair, text)


def _check_known_poses(
    cameras: dict[str, CameraCalibration],
    pose_pairs: Sequence[PairPose],
    tolerances: LoopTolerances,
    reasons: dict[str, list[str]],
) -> None:
    """Whether the poses given beforehand still fit the recording (:mod:`hiros_calib.known`)."""
    usable, _ = _usable_links(pose_pairs, cameras)
    for pose in usable:
        if KNOWN_POSE_RESIDUAL not in pose.quality:
            continue
        known, own = pose.quality[KNOWN_POSE_RESIDUAL], pose.quality[OWN_POSE_RESIDUAL]
        _keep_largest(cameras, pose, KNOWN_POSE_RESIDUAL, known)
        _keep_largest(cameras, pose, OWN_POSE_RESIDUAL, own)
        if known - own > 100 * tolerances.known_pose_excess_m:
            text = (
                f"the known poses fit the {pose.camera_a}-{pose.camera_b} skeletons "
                f"{known - own:.1f} cm worse than a pose fitted to this recording ({known:.1f} "
                f"against {own:.1f} cm; tolerance {100 * tolerances.known_pose_excess_m:.1f}): "
                "a camera has moved since they were calibrated; calibrate a recording of "
                "people walking across the area again"
            )
            _blame_both(reasons, pose, text)


def _resting_on_one_spot(
    name: str, camera: CameraCalibration, tolerances: LoopTolerances, reasons: list[str]
) -> None:
    """A reason when even the camera's best pose pair rests on people who stayed on one spot.

    The joint offsets the solve learns leave the joints' motion about where they stood to fix
    the rotation (``motion_lever_m``, the largest over the camera's pairs); over a short lever
    the body tracker's pose-dependent errors turn it by degrees, alike in every span of time,
    so the split halves cannot show it.
    """
    if "motion_lever_m" not in camera.quality:
        return
    best = _number(camera.quality["motion_lever_m"])
    if best < tolerances.min_motion_lever_m:
        reasons.append(
            f"the pose of {name} rests on joints that barely moved: {ON_ONE_SPOT}, and "
            f"their joints moved {100 * best:.0f} cm RMS about where they "
            f"stood (at least {100 * tolerances.min_motion_lever_m:.0f} cm pin the "
            "rotation down against the body tracker's own errors; record people walking "
            "across the area, or, with the cameras unmoved since such a recording, give its "
            "calibration as --poses-from)"
        )


def _uncertainty(
    cameras: dict[str, CameraCalibration],
    pose: PairPose,
    tolerances: LoopTolerances,
    reasons: dict[str, list[str]],
    links: Counter[str],
) -> None:
    """The pair pose's split-half uncertainty on both cameras; a reason when it is too large.

    The reason goes to a camera whose pose rests on this pair alone (``links``: the pose
    pairs of each camera). A camera with other pairs has its pose solved on all of them; how
    well that pose is pinned down is the split halves of the joint solve
    (:func:`_final_pose_spread`), not of one pair.
    """
    if "split_half_deg" not in pose.quality:
        return
    angle = 0.5 * pose.quality["split_half_deg"]
    distance = 0.005 * pose.quality["split_half_cm"]
    _keep_largest(cameras, pose, "pose_uncertainty_deg", round(angle, 3))
    _keep_largest(cameras, pose, "pose_uncertainty_cm", round(100 * distance, 2))
    if angle > tolerances.uncertainty_deg or distance > tolerances.uncertainty_m:
        lever = pose.quality.get("motion_lever_m")
        text = (
            f"the {pose.camera_a}-{pose.camera_b} pose is poorly determined: two halves of the "
            f"recording give poses {2 * angle:.1f} deg and {200 * distance:.1f} cm apart "
            f"({_loose_pose_advice(lever, tolerances)})"
        )
        for name in (pose.camera_a, pose.camera_b):
            if links[name] == 1:
                reasons[name].append(text)


def _final_pose_spread(
    name: str, camera: CameraCalibration, tolerances: LoopTolerances, reasons: list[str]
) -> None:
    """A reason when the camera's final pose, solved on two halves of the data, moves too far.

    The pairs' own split halves (:func:`_uncertainty`) miss a camera whose pose rests on
    several pairs, each well determined, that disagree; the joint solve on each half
    (:func:`~hiros_calib.extrinsics.solve_poses`) shows it.
    """
    angle = _number(camera.quality.get("pose_split_deg", 0.0))
    distance = 0.01 * _number(camera.quality.get("pose_split_cm", 0.0))
    if angle > tolerances.uncertainty_deg or distance > tolerances.uncertainty_m:
        lever = camera.quality.get("motion_lever_m")
        reasons.append(
            f"the pose of {name} is poorly determined: solved on two halves of the recording "
            f"it moves {angle:.1f} deg and {100 * distance:.1f} cm "
            f"({_loose_pose_advice(lever, tolerances)})"
        )


WALK_ACROSS = (
    "people walking across the whole area pin a pose down better than gestures on the spot"
)
"""What to record instead of people who stayed on one spot."""


def _loose_pose_advice(lever: Any, tolerances: LoopTolerances) -> str:
    """What to record instead of a recording that leaves a pose loose, from how far joints moved.

    ``lever`` is the pose's ``motion_lever_m`` (None: not measured). Where the people walked
    across the area the motion was there and the body tracker's noise is what the halves
    disagree by, which a longer recording averages down; where they gestured on one spot, the
    motion is what was missing.
    """
    if lever is None or _number(lever) < tolerances.min_motion_lever_m:
        return WALK_ACROSS
    return (
        f"the people's joints moved {100 * _number(lever):.0f} cm RMS about their means, so "
        "it is the body tracker's noise that the halves disagree by: a longer recording "
        "averages it down"
    )


def _clock_miss(a: CameraCalibration, b: CameraCalibration, pair: PairOffset) -> float:
    """The pair's measured lag minus the lag the solved clocks give (s), mid-recording."""
    t_b = float(np.median(pair.windows[:, 0])) if len(pair.windows) else 0.0
    t_reference = b.to_reference_time(t_b)
    # invert a's clock model at that reference time
    t_a = (t_reference - a.time_offset + a.drift * a.drift_epoch) / (1 + a.drift)
    return pair.offset - (t_a - t_b)


def _lag_figures(cameras: dict[str, CameraCalibration], pair: PairOffset) -> None:
    """The pair's lag-fit evidence on both cameras (the pair with the larger margin wins)."""
    keys = ("lag_decided_by", "lag_fit_residual_m", "lag_fit_runner_up_m", "lag_fit_margin")
    figures = {f"time_{k}": pair.quality[k] for k in keys if k in pair.quality}
    if not figures:
        return
    for name in (pair.camera_a, pair.camera_b):
        quality = cameras[name].quality
        current = quality.get("time_lag_fit_margin")
        margin = figures.get("time_lag_fit_margin")
        if current is None or (_number(margin) > _number(current)):
            quality.update(figures)


def _combined_rotation(
    name: str,
    camera: CameraCalibration,
    tolerances: LoopTolerances,
    reasons: list[str],
    *,
    one_pair: bool,
) -> None:
    """A reason when the rotation checks, each within tolerance, together are not.

    The pair poses' split halves, the final pose's split halves and the loop's miss are
    three separate signs of how far the rotation is pinned down. Each may stay below its
    tolerance while all three are sizeable, as with one person gesturing on the spot before
    two cameras; their root sum of squares is then taken as the rotation's uncertainty and
    compared with ``rotation_deg``. The pairs' halves count only for a camera whose pose
    rests on ``one_pair``: a pose solved on several pairs has its own halves.
    """
    parts = [
        max(_number(camera.quality.get(key, 0.0)), 0.0)
        for key in ("pose_uncertainty_deg", "pose_split_deg", "loop_rotation_deg")
    ]
    if not one_pair:
        parts[0] = 0.0
    combined = float(np.sqrt(np.sum(np.square(parts))))
    camera.quality["pose_combined_deg"] = round(combined, 3)
    if combined > tolerances.rotation_deg:
        reasons.append(
            f"the pose of {name} is doubtful: its split halves and its loop together put its "
            f"rotation's uncertainty at {combined:.1f} deg (pairs' halves {parts[0]:.1f}, "
            f"the final pose's halves {parts[1]:.1f}, loop {parts[2]:.1f} deg)"
        )


def _number(value: Any) -> float:
    return float("inf") if value == "inf" else float(value) if value is not None else -1.0


def _keep_largest(
    cameras: dict[str, CameraCalibration], pair: PairOffset | PairPose, key: str, value: float
) -> None:
    for name in (pair.camera_a, pair.camera_b):
        quality = cameras[name].quality
        quality[key] = max(value, quality.get(key, 0.0))
