"""A recording's clocks found with the camera poses of an earlier calibration kept.

People who stay on one spot (exercising, gesturing) move their joints too little to pin a
camera's rotation down against the body tracker's own errors (docs/calibration-robustness.md,
session 20), but their motion still times the clocks. Cameras that have not moved since a
recording of people walking across the area keep that recording's poses, and each later
recording, whose clocks may differ (one recording host per camera, an Azure Kinect's device
clock starting at power-on), needs only its clocks. The known poses also make the lag choice
among a repeated motion's alike lags firmer: the skeletons at each lag are measured against the
known pose instead of a pose fitted to them.

Each pair's lag is then checked against every other lag the recording allows
(:func:`check_lags`): under the known poses the joints should lie closest at the chosen lag.
People gesturing on one spot before a noisy SDK lie nearly as close at every lag (16-19 cm),
and the motion can then pick a lag seconds off which the poses, checking only the lags the
motion offers, cannot refute; the whole search can (docs/calibration-robustness.md, session
26).

Whether the cameras are still where the poses say is checked on the recording itself: per
camera pair, the same-instant joints' distance under the known pose (``known_pose_residual_cm``)
against their distance under a pose fitted to this recording alone (``own_pose_residual_cm``,
which is as close as any pose can bring them). A camera moved since fits the known pose
clearly worse and is flagged (:func:`~hiros_calib.quality.flag_cameras`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hiros_calib.extrinsics import CameraPose, PairPose
from hiros_calib.lags import frame_residuals
from hiros_calib.sync import PairOffset
from hiros_calib.sync.params import MIN_OVERLAP
from hiros_calib.tracks import BodyTrack
from hiros_calib.world import place_in_world
from hiros_core.calibration import Calibration
from hiros_core.errors import CalibrationError
from hiros_core.geometry import RigidTransform

__all__ = [
    "KNOWN_POSE_BEST_LAG",
    "KNOWN_POSE_RESIDUAL",
    "OWN_POSE_RESIDUAL",
    "check_lags",
    "keep_known_poses",
    "known_relative_poses",
    "pair_pose",
    "place_as_known",
]

KNOWN_POSE_RESIDUAL = "known_pose_residual_cm"
"""A pose pair's quality key: median per-frame joint distance (cm) under the known poses."""
OWN_POSE_RESIDUAL = "own_pose_residual_cm"
"""A pose pair's quality key: the same under the pair's own pose fitted to this recording."""

KNOWN_POSE_BEST_LAG = "known_pose_best_lag"
"""A clock pair's quality key: the lag (s) at which the known poses fit its skeletons best."""

SEARCH_STEP = 0.05
"""Grid (s) on which every lag of a pair is judged by the known poses (:func:`check_lags`)."""

CHECK_FRAMES = 1200
"""Most instants of one track the lag check judges (a minute on its grid): a long recording's
are spread over it, so that its time and memory stay those of a minute's per pair of tracks."""

BLOCK_VALUES = 2_000_000
"""Coordinates of camera b's points held per block of the distance tables (about 8 MB each)."""

FLOOR_PREFIX = "floor_"
"""The reference camera's quality keys that describe the known calibration's floor."""


def known_relative_poses(
    known: Calibration, cameras: Sequence[str], reference: str
) -> dict[str, RigidTransform]:
    """Each camera's known pose in the reference camera's frame (camera -> reference).

    Raises:
        CalibrationError: a camera the known calibration does not hold.

    """
    missing = [c for c in cameras if c not in known.cameras]
    if missing:
        msg = (
            f"the known poses hold no camera {', '.join(missing)} (they hold "
            f"{', '.join(sorted(known.cameras))}): calibrate a recording in which every camera "
            "sees people walking across the area, then give that calibration"
        )
        raise CalibrationError(msg)
    world_from_reference = known.cameras[reference].extrinsics
    return {c: world_from_reference.inverse() @ known.cameras[c].extrinsics for c in cameras}


def pair_pose(known: dict[str, RigidTransform], camera_a: str, camera_b: str) -> RigidTransform:
    """Camera b's known pose in camera a's frame (b -> a), from :func:`known_relative_poses`."""
    return known[camera_a].inverse() @ known[camera_b]


def keep_known_poses(
    cameras: Sequence[str], known: dict[str, RigidTransform], pose_pairs: Sequence[PairPose]
) -> dict[str, CameraPose]:
    """The known poses of ``cameras``, and each pose pair's figures on how well they fit.

    Adds ``known_pose_residual_cm`` and ``own_pose_residual_cm`` to the quality of every pose
    pair that found one of its own.
    """
    for pair in pose_pairs:
        if pair.ok and pair.reported is not None:
            relative = pair_pose(known, pair.camera_a, pair.camera_b)
            pair.quality[KNOWN_POSE_RESIDUAL] = _median_cm(pair, relative)
            pair.quality[OWN_POSE_RESIDUAL] = _median_cm(pair, pair.transform)
    return {
        camera: CameraPose(camera, "ok", transform=known[camera], quality={"pose": "known"})
        for camera in cameras
    }


def _median_cm(pair: PairPose, transform: RigidTransform) -> float:
    assert pair.reported is not None  # checked by the caller
    residuals = frame_residuals(pair.reported, transform)
    return round(100 * float(np.nanmedian(residuals)), 2) if np.isfinite(residuals).any() else 0.0


def place_as_known(calibration: Calibration, known: Calibration) -> None:
    """Put a calibration solved in its reference camera's frame into the known one's world.

    Its world frame, the floor figures of its reference camera and any camera's flag (a pose
    that was doubtful stays doubtful) come along.
    """
    place_in_world(calibration, known.cameras[calibration.reference].extrinsics)
    calibration.world_frame = known.world_frame
    reference = calibration.cameras[calibration.reference]
    known_reference = known.cameras[calibration.reference]
    reference.quality.update(
        {k: v for k, v in known_reference.quality.items() if k.startswith(FLOOR_PREFIX)}
    )
    for name, camera in calibration.cameras.items():
        doubt = known.cameras[name].flagged
        if doubt:
            note = f"its known pose was flagged: {doubt}"
            camera.flagged = f"{camera.flagged}; {note}" if camera.flagged else note


def check_lags(
    sync_pairs: Sequence[PairOffset],
    tracks: dict[str, list[BodyTrack]],
    known: dict[str, RigidTransform],
) -> None:
    """Add to each timed pair the lag at which the known poses fit its skeletons best.

    ``known_pose_best_lag`` (s, ``tau = t_a - t_b``) in the pair's quality; a lag far from
    the pair's own is flagged (:func:`~hiros_calib.quality.flag_cameras`).
    """
    for pair in sync_pairs:
        if not pair.ok:
            continue
        b_to_a = pair_pose(known, pair.camera_a, pair.camera_b)
        lags, scores = _lag_scores(tracks[pair.camera_a], tracks[pair.camera_b], b_to_a)
        if np.isfinite(scores).any():
            pair.quality[KNOWN_POSE_BEST_LAG] = round(float(lags[np.argmin(scores)]), 3)


def _lag_scores(
    tracks_a: list[BodyTrack],
    tracks_b: list[BodyTrack],
    b_to_a: RigidTransform,
) -> tuple[np.ndarray, np.ndarray]:
    """Lags ``tau = t_a - t_b`` (s) on the search grid and each one's score (m; inf: unseen).

    A lag's score is the mean over camera a's tracks of their median, over their frames, of
    the joint distance to the nearest body camera b saw at that instant (one person's track
    split in two on camera b counts whole). A track needs ``MIN_OVERLAP`` seconds of such
    frames at a lag to count there, and a lag needs half the frames the best-covered lag has.
    """
    grid_a = [_on_grid(t, RigidTransform.identity()) for t in tracks_a]
    grid_b = [_on_grid(t, b_to_a) for t in tracks_b]
    first = min(g[0] for g in grid_a) - max(g[0] + len(g[1]) for g in grid_b)
    last = max(g[0] + len(g[1]) for g in grid_a) - min(g[0] for g in grid_b)
    lags = np.arange(first, last + 1) * SEARCH_STEP
    medians = np.full((len(grid_a), lags.size), np.nan)
    frames = np.zeros((len(grid_a), lags.size))
    for i, (start_a, points_a, mirror) in enumerate(grid_a):
        # a long track is judged on at most CHECK_FRAMES of its instants, spread over it
        stride = max(1, math.ceil(len(points_a) / CHECK_FRAMES))
        kept = np.arange(0, len(points_a), stride)
        least = MIN_OVERLAP / (SEARCH_STEP * stride)
        nearest = np.full((lags.size, len(kept)), np.inf, dtype=np.float32)
        for start_b, points_b, _ in grid_b:
            distance = np.fmin(
                _mean_distance(points_a[kept], points_b),
                _mean_distance(points_a[kept], points_b[:, mirror]),
            )
            # frame ia of a against frame ib of b is lag index start_a + ia - start_b - ib
            base = start_a - start_b - first - len(points_b) + 1
            for k, row in enumerate(distance):
                column = nearest[base + kept[k] : base + kept[k] + len(points_b), k]
                np.fmin(column, row[::-1], out=column)
        seen = np.isfinite(nearest)
        frames[i] = seen.sum(axis=1)
        enough = frames[i] >= least
        if enough.any():
            values = np.where(seen[enough], nearest[enough], np.nan)
            medians[i, enough] = np.nanmedian(values, axis=1)
    counted = np.isfinite(medians)
    total = np.where(counted, frames, 0.0).sum(axis=0)
    scores = np.where(counted, medians, 0.0).sum(axis=0) / np.maximum(counted.sum(axis=0), 1)
    covered = counted.any(axis=0) & (total >= 0.5 * total.max(initial=0.0))
    return lags, np.where(covered, scores, np.inf)


def _on_grid(track: BodyTrack, transform: RigidTransform) -> tuple[int, np.ndarray, np.ndarray]:
    """A track on the search grid: first grid index, ``(G, J, 3)`` points, mirror permutation.

    Each grid point takes the track's nearest frame within half a step (NaN: none, or the
    joint unseen there); the points are moved by ``transform`` into camera a's frame.
    """
    first = math.ceil(track.times[0] / SEARCH_STEP)
    grid = (first + np.arange(math.floor(track.times[-1] / SEARCH_STEP) - first + 1)) * SEARCH_STEP
    nearest = np.clip(np.searchsorted(track.times, grid), 1, len(track.times) - 1)
    nearest -= grid - track.times[nearest - 1] < track.times[nearest] - grid
    points = np.where(track.weights[..., None] > 0, track.positions, np.nan)[nearest]
    points[np.abs(track.times[nearest] - grid) > 0.5 * SEARCH_STEP] = np.nan
    shape = points.shape
    moved = transform.apply(points.reshape(-1, 3)).reshape(shape)
    return first, moved.astype(np.float32), track.layout.mirror


def _mean_distance(points_a: np.ndarray, points_b: np.ndarray) -> np.ndarray:
    """``(A, B)`` mean distance over the joints both frames hold (NaN: none shared)."""
    rows = []
    per_block = max(1, BLOCK_VALUES // max(1, points_b.size))
    for block in np.array_split(np.arange(len(points_a)), max(1, len(points_a) // per_block)):
        gap = np.linalg.norm(points_a[block, None] - points_b[None], axis=-1)  # (a, B, J)
        shared = np.isfinite(gap)
        count = shared.sum(axis=-1)
        total = np.where(shared, gap, 0.0).sum(axis=-1)
        rows.append(np.where(count > 0, total / np.maximum(count, 1), np.nan))
    return np.concatenate(rows)
