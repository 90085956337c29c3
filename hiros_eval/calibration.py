"""Accuracy of an estimated calibration against the true one (simulator truth).

Both calibrations are compared *relative to the estimate's reference camera*: a calibration
from people's motion can only know where the cameras are relative to each other and how their
clocks relate to each other, so the truth (whose world frame and reference clock are the
simulator's) is first re-expressed in the frame and on the clock of the estimate's reference
camera. Errors per camera:

- time: for a camera-clock instant ``t``, the reference-camera time the estimate maps it to
  minus the one the truth maps it to (ms), averaged in absolute value over the given instants
  (clock drift makes the error change over a recording);
- rotation: angle of ``R_est^T R_true`` of the camera-to-reference rotations (degrees);
- translation: distance between the camera positions in the reference camera's frame (cm).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.errors import CalibrationError
from hiros_core.geometry import RigidTransform

__all__ = ["CameraAccuracy", "WorldAccuracy", "compare_calibration", "compare_world"]


@dataclass(frozen=True)
class CameraAccuracy:
    """Errors of one camera's estimated calibration (NaN where the estimate lacks it)."""

    camera: str
    time_error_ms: float
    time_error_max_ms: float
    rotation_error_deg: float
    translation_error_cm: float


def _inverse_clock(cam: CameraCalibration, t_reference: np.ndarray) -> np.ndarray:
    """Reference-clock seconds back to the camera's clock (inverse of the DESIGN.md model)."""
    return (t_reference - cam.time_offset + cam.drift * cam.drift_epoch) / (1.0 + cam.drift)


def _on_camera_clock(
    calibration: Calibration, camera: str, reference: str, t: np.ndarray
) -> np.ndarray:
    """Camera ``camera``'s instants ``t`` expressed on camera ``reference``'s clock."""
    cam, ref = calibration.camera(camera), calibration.camera(reference)
    return _inverse_clock(ref, np.asarray(cam.to_reference_time(t)))


def _in_camera_frame(calibration: Calibration, camera: str, reference: str) -> RigidTransform:
    """Camera ``camera``'s pose in camera ``reference``'s frame."""
    return (
        calibration.camera(reference).extrinsics.inverse() @ calibration.camera(camera).extrinsics
    )


def compare_calibration(
    estimated: Calibration,
    truth: Calibration,
    times: Mapping[str, np.ndarray] | None = None,
) -> dict[str, CameraAccuracy]:
    """Per-camera time (ms), rotation (deg) and translation (cm) errors of ``estimated``.

    Args:
        estimated: the calibration to judge; its reference camera defines frame and clock.
        truth: the true calibration (any world frame and reference clock).
        times: per camera, camera-clock instants (s) where the time error is measured;
            default: the true ``drift_epoch`` of the camera (one instant).

    Returns:
        One entry per camera of the truth other than the reference, NaN errors where the
        estimate has no such camera.

    Raises:
        CalibrationError: the estimate's reference camera is not in the truth.

    """
    reference = estimated.reference
    if reference not in truth.cameras:
        msg = f"the estimate's reference camera {reference!r} is not in the truth calibration"
        raise CalibrationError(msg)
    out = {}
    for camera, true_cam in truth.cameras.items():
        if camera == reference:
            continue
        if camera not in estimated.cameras:
            out[camera] = CameraAccuracy(camera, math.nan, math.nan, math.nan, math.nan)
            continue
        t = np.atleast_1d(
            np.asarray(times[camera] if times and camera in times else true_cam.drift_epoch)
        ).astype(float)
        time_error = _on_camera_clock(estimated, camera, reference, t) - _on_camera_clock(
            truth, camera, reference, t
        )
        pose_est = _in_camera_frame(estimated, camera, reference)
        pose_true = _in_camera_frame(truth, camera, reference)
        angle = math.degrees((pose_est.rotation.inv() * pose_true.rotation).magnitude())
        distance = float(np.linalg.norm(pose_est.translation - pose_true.translation))
        out[camera] = CameraAccuracy(
            camera,
            float(1e3 * np.mean(np.abs(time_error))),
            float(1e3 * np.max(np.abs(time_error))),
            angle,
            100.0 * distance,
        )
    return out


@dataclass(frozen=True)
class WorldAccuracy:
    """How far an estimated world's up and floor are from a z-up truth with the floor at z = 0."""

    up_error_deg: float
    """Angle between the estimate's z axis and the truth's."""
    floor_error_cm: float
    """Height of the true floor in the estimated world at the chosen place (0: exact;
    negative: the estimated floor is above the true one)."""


def compare_world(estimated: Calibration, truth: Calibration, at: np.ndarray) -> WorldAccuracy:
    """The estimate's world against a z-up, floor-at-zero truth, through the reference camera.

    Args:
        estimated: a calibration in a gravity-aligned world (``world`` = floor).
        truth: the true calibration, its world z up with the floor at z = 0.
        at: ``(2,)`` the place on the true floor (truth x, y) where the floor is compared,
            e.g. where the people walked: a tilted estimate is off by more further away.

    """
    reference = estimated.reference
    truth_from_estimate = (
        truth.camera(reference).extrinsics @ estimated.camera(reference).extrinsics.inverse()
    )
    up = truth_from_estimate.rotate(np.array([0.0, 0.0, 1.0]))
    angle = math.degrees(math.acos(float(np.clip(up[2], -1.0, 1.0))))
    floor = truth_from_estimate.inverse().apply(np.array([at[0], at[1], 0.0]))
    return WorldAccuracy(angle, 100.0 * float(floor[2]))
