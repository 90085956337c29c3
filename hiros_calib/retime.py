"""Each camera's clock refined by the skeletons' motion, once the camera poses are known.

The correlation of pose signatures (:mod:`~hiros_calib.sync`) times each camera pair to a few
milliseconds, and the spread of its windows says how well. With the poses known, the
same-instant joints give a second, independent measure. When camera b's clock is off by
``eps`` against camera a's, the joints b reports at what the clocks call the same instant are
where they were ``eps`` later, so in camera a's frame::

    r = p_a - T p_b  =  -v eps + d + noise

with ``v`` the joint's velocity (the mean of both cameras' central differences) and ``d`` the
SDKs' constant offset of that joint of that person. Least squares over every frame and joint
(``d`` removed per body pair and joint, residuals beyond ``OUTLIER_FACTOR`` times their median
left out, left and right taken as b reported them or swapped, whichever fits) gives ``eps``.
Since the shift also moves where b is interpolated, it is solved again at the shifted clocks
(up to ``MAX_PASSES``). Its standard error is clustered over ``BLOCK`` seconds, the SDKs' errors
being correlated over time.

Each camera's offset is then the weighted combination of both measures: the correlation's
clocks, with the information their pairs' window spreads give, and every pair's motion
shift, with ``SHIFT_SE_INFLATION`` times its standard error (on the noisier SDK the clustered
error understates the spread against the truth by about that much). Where the correlation is
sure (many windows that agree), the clocks hardly move; where it rests on a few scattered
windows, the motion decides. Drifts are kept. Figures: docs/calibration-robustness.md.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from hiros_calib.extrinsics import CameraPose, ExtrinsicsParams, PairPose, joint_tables
from hiros_calib.extrinsics.params import MAX_INTERPOLATION_GAP
from hiros_calib.sync import CameraClock, PairOffset
from hiros_calib.tracks import BodyTrack
from hiros_core.geometry import RigidTransform

__all__ = ["MotionShift", "motion_shift", "retime"]

VELOCITY_SPAN = 0.1
"""Half the span (s) of the central difference a joint's velocity is taken over: long enough
that the SDK's noise does not swamp it, short against a limb's swing (a 1 Hz motion keeps
94 % of its speed)."""

BLOCK = 1.0
"""Seconds of frames whose contributions to the shift are summed before their spread is taken
(the standard error's clusters)."""

OUTLIER_FACTOR = 3.0
"""Residuals beyond this many times their median are left out (misread flips, swaps)."""

MAX_PASSES = 8
"""Most passes of the shift, each at the clocks the previous one left. The velocity's noise
attenuates a measured shift (to about 0.8 of the clock error on real data, less on a noisy
SDK), so the passes approach the combination in steps; a last one measures what is left."""

CONVERGED = 0.0002
"""The passes stop once no offset moves by more than this (s)."""

FRAME_STEP = 2
"""Every this many frames of camera a are used: the SDKs' errors are correlated over several
frames, so the others add little, and this pass runs on every calibration."""

SHIFT_SE_INFLATION = 2.0
"""Factor on a motion shift's clustered standard error when it is weighed against the
correlation's clocks."""

WINDOW_SE_FLOOR = 0.001
"""Smallest standard error (s) a correlation pair is credited with."""

LONE_WINDOW_SE = 0.01
"""Standard error (s) of a correlation pair measured in a single window (no spread to judge)."""

MAX_SHIFT = 0.1
"""A pair whose motion shift is larger (s) is left out: the linear model holds for a few
frames at most, and a shift that large is a doubt for the lag checks, not a refinement."""


@dataclass(frozen=True)
class MotionShift:
    """How far camera b's clock is off against camera a's by the joints' motion.

    Attributes:
        camera_a, camera_b: the pair.
        shift: ``eps`` (s): add it to b's offset (or take it from a's).
        standard_error: its clustered standard error (s).
        samples: joint samples used.

    """

    camera_a: str
    camera_b: str
    shift: float
    standard_error: float
    samples: int


def motion_shift(
    pose: PairPose,
    tracks: dict[str, list[BodyTrack]],
    clocks: dict[str, CameraClock],
    b_to_a: RigidTransform,
    params: ExtrinsicsParams,
) -> MotionShift | None:
    """The motion shift of one camera pair's clocks (module docstring); None without motion."""
    a, b = pose.camera_a, pose.camera_b
    parts = [
        _body_pair_terms(tracks[a][i], tracks[b][j], clocks[a], clocks[b], b_to_a, params)
        for i, j in pose.body_pairs
    ]
    parts = [p for p in parts if p is not None]
    if not parts:
        return None
    residual, velocity, weight, times = (np.concatenate(k) for k in zip(*parts, strict=True))
    size = np.linalg.norm(residual, axis=2)
    used = weight > 0
    if not used.any():
        return None
    weight = np.where(size < OUTLIER_FACTOR * np.median(size[used]), weight, 0.0)
    speed2 = (weight * (velocity * velocity).sum(axis=2)).sum()
    if not speed2 > 0:
        return None
    shift = -float((weight * (velocity * residual).sum(axis=2)).sum() / speed2)
    left = residual + velocity * shift
    per_frame = -(weight * (velocity * left).sum(axis=2)).sum(axis=1) / speed2
    _, block = np.unique(np.floor(times / BLOCK), return_inverse=True)
    error = math.sqrt(float((np.bincount(block, per_frame) ** 2).sum()))
    return MotionShift(a, b, shift, error, int((weight > 0).sum()))


def _body_pair_terms(  # noqa: PLR0917 - one body pair of one camera pair
    track_a: BodyTrack,
    track_b: BodyTrack,
    clock_a: CameraClock,
    clock_b: CameraClock,
    b_to_a: RigidTransform,
    params: ExtrinsicsParams,
) -> tuple[np.ndarray, ...] | None:
    """Residuals, velocities ``(F, K, 3)``, weights ``(F, K)`` and times ``(F,)`` of a body pair.

    Residuals are in camera a's frame, each joint's mean over the pair removed.
    """
    joints, mirror, _ = joint_tables(track_a.layout, params.pose_joints)
    frames = slice(None, None, FRAME_STEP)
    times = track_a.times[frames]
    t_b = np.asarray(clock_b.from_reference(clock_a.to_reference(times)))
    around = (VELOCITY_SPAN, -VELOCITY_SPAN)
    samples = [track_a.at(times + d, MAX_INTERPOLATION_GAP) for d in around]
    samples += [track_b.at(t_b + d, MAX_INTERPOLATION_GAP) for d in (0.0, *around)]
    (a_up, wa_up), (a_down, wa_down), (b_now, wb_now), (b_up, wb_up), (b_down, wb_down) = samples
    point_b = b_to_a.apply(b_now[:, joints].reshape(-1, 3)).reshape(len(times), -1, 3)
    speed_a = (a_up - a_down)[:, joints] / (2 * VELOCITY_SPAN)
    speed_b = b_to_a.rotate((b_up - b_down)[:, joints].reshape(-1, 3)).reshape(point_b.shape)
    speed_b /= 2 * VELOCITY_SPAN
    weight = np.minimum.reduce([track_a.weights[frames], wa_up, wa_down, wb_now, wb_up, wb_down])[
        :, joints
    ]
    point_a = track_a.positions[frames, joints]
    straight, swapped = point_a - point_b, point_a - point_b[:, mirror]
    weight_swapped = np.minimum(weight, weight[:, mirror])
    swap = np.nansum(weight_swapped * np.linalg.norm(swapped, axis=2), axis=1) < np.nansum(
        weight * np.linalg.norm(straight, axis=2), axis=1
    )
    residual = np.where(swap[:, None, None], swapped, straight)
    velocity = 0.5 * (speed_a + np.where(swap[:, None, None], speed_b[:, mirror], speed_b))
    weight = np.where(swap[:, None], weight_swapped, weight)
    finite = np.isfinite(residual).all(axis=2) & np.isfinite(velocity).all(axis=2)
    weight = np.where(finite, weight, 0.0)
    if not (weight > 0).any():
        return None
    residual, velocity = np.nan_to_num(residual), np.nan_to_num(velocity)
    mean = (weight[:, :, None] * residual).sum(axis=0) / np.maximum(weight.sum(axis=0), 1e-12)[
        :, None
    ]
    return residual - mean, velocity, weight, times


def retime(
    clocks: dict[str, CameraClock],
    reference: str,
    *,
    sync_pairs: list[PairOffset],
    pose_pairs: list[PairPose],
    poses: dict[str, CameraPose],
    tracks: dict[str, list[BodyTrack]],
    params: ExtrinsicsParams,
) -> tuple[dict[str, CameraClock], list[MotionShift]]:
    """Clocks with their offsets refined by the motion (module docstring), and the shifts.

    ``clocks`` is left as it was; the returned clocks are copies. Each refined camera's
    quality gains ``motion_shift_ms``: how far the motion moved its offset. The shifts are
    every pair's, measured at the returned clocks (what is left between the two measures).
    """
    clocks = copy.deepcopy(clocks)
    cameras = [
        c
        for c, clock in clocks.items()
        if c != reference and clock.ok and c in poses and poses[c].ok
    ]
    prior = _correlation_information(sync_pairs, cameras)
    pairs = [p for p in pose_pairs if p.ok and {p.camera_a, p.camera_b} <= {reference, *cameras}]
    if not cameras or not pairs:
        return clocks, []
    total = np.zeros(len(cameras))
    for _ in range(MAX_PASSES):
        shifts = _measure(pairs, tracks, clocks, poses, params)
        if not shifts:
            break
        design = np.array([_incidence(s.camera_a, s.camera_b, cameras) for s in shifts])
        measured = np.array([s.shift for s in shifts]) + design @ total
        weight = 1.0 / (SHIFT_SE_INFLATION * np.array([s.standard_error for s in shifts])) ** 2
        information = prior + design.T @ (weight[:, None] * design)
        solution = np.linalg.lstsq(information, design.T @ (weight * measured), rcond=None)[0]
        steps = solution - total
        for camera, step in zip(cameras, steps, strict=True):
            clocks[camera].time_offset += float(step)
        total = solution
        if np.abs(steps).max() < CONVERGED:
            break
    for camera, moved in zip(cameras, total, strict=True):
        clocks[camera].quality["motion_shift_ms"] = round(1e3 * float(moved), 3)
    return clocks, _measure(pairs, tracks, clocks, poses, params)


def _measure(
    pairs: list[PairPose],
    tracks: dict[str, list[BodyTrack]],
    clocks: dict[str, CameraClock],
    poses: dict[str, CameraPose],
    params: ExtrinsicsParams,
) -> list[MotionShift]:
    """Every pair's motion shift at ``clocks``, those beyond ``MAX_SHIFT`` left out."""
    shifts = []
    for pair in pairs:
        b_to_a = poses[pair.camera_a].transform.inverse() @ poses[pair.camera_b].transform
        found = motion_shift(pair, tracks, clocks, b_to_a, params)
        if found is not None and abs(found.shift) <= MAX_SHIFT and found.standard_error > 0:
            shifts.append(found)
    return shifts


def _incidence(camera_a: str, camera_b: str, cameras: list[str]) -> np.ndarray:
    """A pair's row over the non-reference cameras' offsets: +1 for b, -1 for a."""
    row = np.zeros(len(cameras))
    if camera_b in cameras:
        row[cameras.index(camera_b)] += 1.0
    if camera_a in cameras:
        row[cameras.index(camera_a)] -= 1.0
    return row


def _correlation_information(pairs: list[PairOffset], cameras: list[str]) -> np.ndarray:
    """``(C, C)`` information (inverse covariance) on the offsets from the correlation's pairs.

    Each usable pair counts with the standard error of its windows' weighted mean lag.
    """
    information = np.zeros((len(cameras), len(cameras)))
    for pair in pairs:
        if not pair.ok or not len(pair.windows):
            continue
        lags, weights = pair.windows[:, 1], pair.windows[:, 2]
        if len(lags) < 2 or not weights.sum() > 0:
            error = LONE_WINDOW_SE
        else:
            mean = np.average(lags, weights=weights)
            spread = math.sqrt(float(np.average((lags - mean) ** 2, weights=weights)))
            error = max(spread / math.sqrt(len(lags)), WINDOW_SE_FLOOR)
        row = _incidence(pair.camera_a, pair.camera_b, cameras)
        information += np.outer(row, row) / error**2
    return information
