"""A recording's clocks found with the camera poses of an earlier calibration kept.

People who stay on one spot (exercising, gesturing) move their joints too little to pin a
camera's rotation down against the body tracker's own errors (docs/calibration-robustness.md,
session 20), but their motion still times the clocks. Cameras that have not moved since a
recording of people walking across the area keep that recording's poses, and each later
recording, whose clocks may differ (one recording host per camera, an Azure Kinect's device
clock starting at power-on), needs only its clocks. The known poses also make the lag choice
among a repeated motion's alike lags firmer: the skeletons at each lag are measured against the
known pose instead of a pose fitted to them.

Whether the cameras are still where the poses say is checked on the recording itself: per
camera pair, the same-instant joints' distance under the known pose (``known_pose_residual_cm``)
against their distance under a pose fitted to this recording alone (``own_pose_residual_cm``,
which is as close as any pose can bring them). A camera moved since fits the known pose
clearly worse and is flagged (:func:`~hiros_calib.quality.flag_cameras`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hiros_calib.extrinsics import CameraPose, PairPose
from hiros_calib.lags import frame_residuals
from hiros_calib.world import place_in_world
from hiros_core.calibration import Calibration
from hiros_core.errors import CalibrationError
from hiros_core.geometry import RigidTransform

__all__ = [
    "KNOWN_POSE_RESIDUAL",
    "OWN_POSE_RESIDUAL",
    "keep_known_poses",
    "known_relative_poses",
    "place_as_known",
]

KNOWN_POSE_RESIDUAL = "known_pose_residual_cm"
"""A pose pair's quality key: median per-frame joint distance (cm) under the known poses."""
OWN_POSE_RESIDUAL = "own_pose_residual_cm"
"""A pose pair's quality key: the same under the pair's own pose fitted to this recording."""

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


def keep_known_poses(
    cameras: Sequence[str], known: dict[str, RigidTransform], pose_pairs: Sequence[PairPose]
) -> dict[str, CameraPose]:
    """The known poses of ``cameras``, and each pose pair's figures on how well they fit.

    Adds ``known_pose_residual_cm`` and ``own_pose_residual_cm`` to the quality of every pose
    pair that found one of its own.
    """
    for pair in pose_pairs:
        if pair.ok and pair.reported is not None:
            relative = known[pair.camera_a].inverse() @ known[pair.camera_b]
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
