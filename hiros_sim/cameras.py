"""Simulated cameras: where they stand, where they look, and their clocks.

Each camera's depth frame is x right, y down, z forward (the Azure Kinect depth camera and the
``<cam>_depth_camera_link`` frame of the driver). A camera stands on a circle around the room
centre at a height between ``height_range``, looks at a point 1 m above the centre of the room
and is pitched down by that aim plus ``tilt_range`` degrees, so people's feet stay in view.

Setups:

===========  ======================================================================
setup        cameras
===========  ======================================================================
``room``     N cameras (default 3): k01 and k02 face each other (180° apart), the others
             spread over one side of the circle between them
``facing``   2 cameras 180° apart
``ring``     N cameras evenly spaced around the circle
``pair``     2 cameras side by side at the same height and tilt, both facing the scene:
             their views ``pair_angle`` degrees apart, ``pair_baseline`` metres between
             them (each drawn uniformly from its range), so they stand
             ``baseline / (2 sin(angle / 2))`` from the room centre (about 1.8 m) instead
             of ``radius``
a YAML file  the poses of a calibration file (DESIGN.md format); its clock figures are
             kept when non-zero
===========  ======================================================================

Clocks: the reference clock is k01's (offset 0, drift 0), and it reads ``clock_start`` (a Unix
time, like the driver's host stamps) at simulation time 0. Every other camera gets an offset
uniform in ``±max_time_offset`` seconds and a drift drawn from N(0, ``drift_ppm``) parts per
million, with ``drift_epoch`` its own clock's start, so that
``t_reference = t_camera + time_offset + drift (t_camera - drift_epoch)`` (DESIGN.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.calibration import Calibration, CameraCalibration, load_calibration
from hiros_core.errors import ConfigError

__all__ = ["camera_names", "camera_to_reference", "look_at", "make_setup", "reference_to_camera"]


def camera_names(count: int) -> list[str]:
    """``k01``, ``k02``, ... (the Azure driver's usual namespaces)."""
    return [f"k{i + 1:02d}" for i in range(count)]


def look_at(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) of a camera at ``position`` looking at ``target``, world Z up.

    Columns of the camera -> world rotation are the camera axes in the world: x right
    (forward × up), y down (forward × right), z forward.
    """
    forward = np.asarray(target, float) - np.asarray(position, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    quat = Rotation.from_matrix(np.column_stack([right, down, forward])).as_quat()
    return -quat if quat[3] < 0 else quat


_SETUPS = ("room", "facing", "ring", "pair")


def _azimuths(setup: str, count: int) -> np.ndarray:
    if setup == "facing":
        return np.array([0.0, np.pi])
    if setup == "ring":
        return 2.0 * np.pi * np.arange(count) / count
    # room: a facing pair, then the others spread over the side between them
    extra = count - 2
    if extra <= 0:
        return np.array([0.0, np.pi])[:count]
    side = np.pi * (np.arange(extra) + 1) / (extra + 1)
    return np.concatenate([[0.0, np.pi], side])


def make_setup(
    setup: str,
    count: int,
    rng: np.random.Generator,
    *,
    radius: float,
    height_range: tuple[float, float],
    tilt_range: tuple[float, float],
    max_time_offset: float,
    drift_ppm: float,
    clock_start: float,
    pair_angle: tuple[float, float] = (40.0, 50.0),
    pair_baseline: tuple[float, float] = (1.3, 1.5),
) -> Calibration:
    """The true calibration of a camera setup (poses camera -> world, clocks)."""
    if setup in _SETUPS:
        if count < 1 or (setup in {"facing", "pair"} and count != 2):
            count = 2 if setup in {"facing", "pair"} else count
        if count < 1:
            msg = "a simulation needs at least one camera"
            raise ConfigError(msg)
        azimuths = _azimuths(setup, count)
        if setup == "pair":
            angle = np.deg2rad(rng.uniform(*pair_angle))
            radius = rng.uniform(*pair_baseline) / (2.0 * np.sin(0.5 * angle))
            azimuths = np.array([-0.5 * angle, 0.5 * angle])
            pair_height = rng.uniform(*height_range)
            pair_tilt = np.deg2rad(rng.uniform(*tilt_range))
        calibration = Calibration(reference="k01", world_frame="world")
        for name, azimuth in zip(camera_names(count), azimuths, strict=True):
            if setup == "pair":  # a symmetric pair: one height and tilt for both
                height, tilt = pair_height, pair_tilt
            else:
                height = rng.uniform(*height_range)
                tilt = np.deg2rad(rng.uniform(*tilt_range))
            # aim at 1 m above the centre, then pitch further down by the tilt
            position = np.array([radius * np.cos(azimuth), radius * np.sin(azimuth), height])
            target = np.array([0.0, 0.0, 1.0]) + np.array([0.0, 0.0, -radius * np.tan(tilt)])
            calibration.cameras[name] = CameraCalibration(
                frame_id=f"{name}_depth_camera_link",
                translation=position,
                rotation=look_at(position, target),
            )
    else:
        path = Path(setup)
        if not path.is_file():
            msg = f"camera setup {setup!r} is neither {', '.join(_SETUPS)} nor a calibration file"
            raise ConfigError(msg)
        calibration = load_calibration(path)
    _draw_clocks(calibration, rng, max_time_offset, drift_ppm, clock_start)
    return calibration


def _draw_clocks(
    calibration: Calibration,
    rng: np.random.Generator,
    max_time_offset: float,
    drift_ppm: float,
    clock_start: float,
) -> None:
    for name, cam in calibration.cameras.items():
        if not cam.frame_id:
            cam.frame_id = f"{name}_depth_camera_link"
        if name == calibration.reference:
            cam.time_offset, cam.drift = 0.0, 0.0
            cam.drift_epoch = clock_start
            continue
        if cam.time_offset == 0.0 and cam.drift == 0.0:
            cam.time_offset = float(rng.uniform(-max_time_offset, max_time_offset))
            cam.drift = float(rng.normal(0.0, drift_ppm * 1e-6))
            cam.drift_epoch = float(np.round(clock_start - cam.time_offset, 3))


def camera_to_reference(cam: CameraCalibration, t_camera: np.ndarray) -> np.ndarray:
    """Camera-clock seconds to reference seconds (DESIGN.md formula)."""
    return t_camera + cam.time_offset + cam.drift * (t_camera - cam.drift_epoch)


def reference_to_camera(cam: CameraCalibration, t_reference: np.ndarray) -> np.ndarray:
    """Reference seconds to camera-clock seconds (the inverse of the DESIGN.md formula)."""
    return (t_reference - cam.time_offset + cam.drift * cam.drift_epoch) / (1.0 + cam.drift)
