"""A gravity-aligned world frame from the people: z up, the floor at z = 0 (REP-103).

The calibration solves every camera's pose relative to the reference camera, whose optical
frame has y down and z forward and is tilted as the camera happens to be. People stand on the
floor, so they tell where it is:

- **Up.** Where people walk around, the places their feet rest (a foot joint that hardly
  moves) lie on a plane parallel to the floor: its normal is up. Where the feet stay in one
  small area (gestures on the spot), that plane is not pinned down and the body's mean
  vertical (pelvis to neck, averaged over the frames) is used instead, kept perpendicular to
  the direction the resting feet do spread along.
- **The floor.** The resting feet's median height along up, less the height of the foot
  joint above the floor when the foot rests (:data:`FOOT_JOINT_HEIGHT`).
- **The axes.** x along the reference camera's view projected on the floor, y to its left,
  the origin on the floor below the reference camera.

Every camera's pose then becomes ``world <- reference <- camera``. The fit's figures (how far
the resting feet lie from the plane, the tilt it corrected, what up came from) go into the
reference camera's quality.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_calib.tracks import BodyTrack
from hiros_core.calibration import Calibration
from hiros_core.geometry import RigidTransform

__all__ = ["FOOT_JOINT_HEIGHT", "FloorFit", "align_to_floor", "fit_floor", "place_in_world"]

FOOT_JOINT_HEIGHT = {"Foot": 0.06, "Ankle": 0.09}
"""Height (m) of a resting foot's joint above the floor, by joint: the body-tracking SDKs'
foot joint sits in the forefoot, the ankle joint above the heel (both include the heel rising
during a step's stance)."""

RESTING_SPEED = 0.15
"""A foot joint slower than this (m/s) is taken to rest on the floor."""

SPEED_BASELINE = 0.4
"""Seconds over which a foot's speed is measured."""

MIN_SPREAD = 0.25
"""Resting feet must spread this far (m, standard deviation) in two directions for their plane
to give up; otherwise the body's vertical does."""


@dataclass
class FloorFit:
    """Up and the floor in the reference camera's frame, with how well they were found."""

    up: np.ndarray
    """``(3,)`` unit vector, reference camera frame."""
    floor_height: float
    """The floor's position along ``up`` (m): points ``p`` with ``p @ up == floor_height``."""
    residual_m: float
    """RMS distance of the resting feet from their plane (m)."""
    points: int
    """Resting-foot samples used."""
    source: str
    """``"feet"`` (their plane) or ``"body"`` (the mean pelvis-to-neck direction)."""

    def quality(self) -> dict[str, Any]:
        """The figures for the calibration file."""
        tilt = math.degrees(math.acos(float(np.clip(-self.up[1], -1.0, 1.0))))
        return {
            "floor_residual_cm": round(100 * self.residual_m, 2),
            "floor_tilt_deg": round(tilt, 2),
            "floor_points": self.points,
            "floor_up_from": self.source,
        }


def _joint(track: BodyTrack, names: tuple[str, ...]) -> list[int]:
    return [track.layout.joint_names.index(n) for n in names if n in track.layout.joint_names]


def _resting_feet(track: BodyTrack) -> tuple[np.ndarray, float] | None:
    """``(N, 3)`` resting foot positions (camera frame) and their joint's height, or None."""
    for kind, height in FOOT_JOINT_HEIGHT.items():
        joints = _joint(track, (f"{kind}Left", f"{kind}Right"))
        if len(joints) == 2 and len(track.times) >= 3:
            positions = track.positions[:, joints]  # (T, 2, 3)
            resting = (_speed(positions, track.times) < RESTING_SPEED) & (
                track.weights[:, joints] > 0
            )
            return positions[resting], height
    return None


def _speed(positions: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``(T, K)`` speed (m/s) over ``SPEED_BASELINE``, NaN at the ends.

    Frame to frame, the SDKs' jitter alone would make a resting foot seem to move at
    decimetres per second.
    """
    speed = np.full(positions.shape[:2], np.nan)
    step = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    half = max(1, round(0.5 * SPEED_BASELINE / step)) if step > 0 else 1
    if len(times) <= 2 * half:
        return speed
    moved = np.linalg.norm(positions[2 * half :] - positions[: -2 * half], axis=2)
    elapsed = (times[2 * half :] - times[: -2 * half])[:, None]
    speed[half:-half] = moved / elapsed
    return speed


def _body_vertical(track: BodyTrack) -> np.ndarray | None:
    """``(T, 3)`` pelvis-to-neck unit vectors (camera frame), or None without those joints."""
    joints = _joint(track, ("Pelvis", "Neck")) or _joint(track, ("SpineBase", "SpineShoulder"))
    if len(joints) != 2:
        return None
    spine = track.positions[:, joints[1]] - track.positions[:, joints[0]]
    norm = np.linalg.norm(spine, axis=1, keepdims=True)
    ok = np.isfinite(norm[:, 0]) & (norm[:, 0] > 0.2)
    return spine[ok] / norm[ok]


def fit_floor(
    tracks: dict[str, list[BodyTrack]], poses: dict[str, RigidTransform]
) -> FloorFit | None:
    """Up and the floor height in the reference frame from every camera's tracks.

    ``poses`` maps each camera to its ``reference <- camera`` transform. None when no
    camera saw a body with both a vertical and resting feet.
    """
    feet, heights, verticals = [], [], []
    for camera, pose in poses.items():
        for track in tracks.get(camera, []):
            rest = _resting_feet(track)
            if rest is not None and len(rest[0]):
                points = pose.apply(rest[0])
                feet.append(points[np.isfinite(points).all(axis=1)])
                heights.append(np.full(len(feet[-1]), rest[1]))
            vertical = _body_vertical(track)
            if vertical is not None and len(vertical):
                verticals.append(pose.rotate(vertical))
    if not feet or not verticals:
        return None
    points, joint_height = np.concatenate(feet), np.concatenate(heights)
    body_up = np.concatenate(verticals).mean(axis=0)
    body_up /= np.linalg.norm(body_up)
    if len(points) < 10:
        return None
    up, source = _up(points, body_up)
    along = points @ up - joint_height
    floor = float(np.median(along))
    spread = along - floor
    inliers = np.abs(spread) < 3 * max(1.4826 * float(np.median(np.abs(spread))), 0.005)
    residual = float(np.sqrt(np.mean(spread[inliers] ** 2)))
    return FloorFit(up, floor, residual, int(inliers.sum()), source)


def _up(points: np.ndarray, body_up: np.ndarray) -> tuple[np.ndarray, str]:
    """Up from the resting feet's plane where they spread widely, else the body's vertical."""
    values, vectors = np.linalg.eigh(np.cov((points - np.median(points, axis=0)).T))
    spreads = np.sqrt(np.maximum(values, 0.0))  # ascending
    if spreads[1] >= MIN_SPREAD:
        normal = _robust_plane_normal(points, vectors[:, 0])
        return (normal if normal @ body_up > 0 else -normal), "feet"
    if spreads[2] >= MIN_SPREAD:
        # feet along one line (walking to and fro): up is perpendicular to it
        line = vectors[:, 2]
        up = body_up - (body_up @ line) * line
        return up / np.linalg.norm(up), "body"
    return body_up, "body"


def _robust_plane_normal(points: np.ndarray, normal: np.ndarray, rounds: int = 8) -> np.ndarray:
    """The normal of the plane best fitting ``points``, Cauchy-reweighted from ``normal``.

    A foot joint the SDK misplaces by decimetres would tilt a least-squares plane.
    """
    weights = np.ones(len(points))
    for _ in range(rounds):
        centre = np.average(points, axis=0, weights=weights)
        centred = points - centre
        distance = centred @ normal
        scale = max(1.4826 * float(np.median(np.abs(distance - np.median(distance)))), 0.005)
        weights = 1.0 / (1.0 + (distance / (2.0 * scale)) ** 2)
        covariance = (centred * weights[:, None]).T @ centred
        normal = np.linalg.eigh(covariance)[1][:, 0]
    return normal


def align_to_floor(calibration: Calibration, floor: FloorFit) -> None:
    """Re-express every camera's pose in the floor's world (in place), figures included.

    Before, the world is the reference camera's frame; after, z is up, the floor is z = 0 and
    x is the reference camera's view projected on the floor.
    """
    up = floor.up
    view = np.array([0.0, 0.0, 1.0]) - up[2] * up  # the optical z axis, on the floor
    if np.linalg.norm(view) < 1e-6:  # a camera looking straight down: its x axis instead
        view = np.array([1.0, 0.0, 0.0]) - up[0] * up
    x = view / np.linalg.norm(view)
    y = np.cross(up, x)
    rows = np.stack([x, y, up])  # reference frame -> world coordinates
    # the origin is the floor below the reference camera (the reference frame's origin)
    below = floor.floor_height * up
    # (re-orthonormalised: x, y and up are orthogonal up to rounding)
    rotation = Rotation.from_matrix(rows)
    place_in_world(calibration, RigidTransform(rotation, -rotation.apply(below)))
    reference = calibration.cameras[calibration.reference]
    reference.quality.update(floor.quality())


def place_in_world(calibration: Calibration, world_from_reference: RigidTransform) -> None:
    """Re-express every pose of a calibration solved in its reference camera's frame (in place).

    ``world_from_reference`` is where the reference camera's frame sits in the new world.
    """
    for cam in calibration.cameras.values():
        placed = world_from_reference @ cam.extrinsics
        cam.translation, cam.rotation = placed.translation, placed.quaternion
