"""Small synthetic multi-camera scenes for the tracker tests: walking people seen by a camera ring.

Handed out as the ``scenes`` fixture (a namespace of the helpers below) because tests run with
``--import-mode=importlib``, where test modules cannot import sibling modules.

World frame z up; cameras (Azure convention: x right, y down, z forward) on a ring looking at
the centre. A person is a fixed-limb-length 32-joint pose (AZURE_KINECT) placed on a path with a
swinging gait, so limb lengths stay constant while joints move.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pytest

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup

# (left, forward, up) metres of each joint of a person standing at the origin facing forward.
_TEMPLATE = {
    "Pelvis": (0.0, 0.0, 0.95), "SpineNaval": (0.0, 0.0, 1.1), "SpineChest": (0.0, 0.0, 1.3),
    "Neck": (0.0, 0.0, 1.5), "Head": (0.0, 0.02, 1.65), "Nose": (0.0, 0.1, 1.62),
    "ClavicleLeft": (0.05, 0.0, 1.45), "ShoulderLeft": (0.18, 0.0, 1.42),
    "ElbowLeft": (0.22, 0.0, 1.15), "WristLeft": (0.24, 0.02, 0.9),
    "HandLeft": (0.25, 0.03, 0.83), "HandTipLeft": (0.25, 0.04, 0.76),
    "ThumbLeft": (0.23, 0.06, 0.84), "HipLeft": (0.1, 0.0, 0.92), "KneeLeft": (0.1, 0.02, 0.5),
    "AnkleLeft": (0.1, 0.0, 0.08), "FootLeft": (0.1, 0.12, 0.02), "EyeLeft": (0.03, 0.08, 1.67),
    "EarLeft": (0.07, 0.0, 1.65),
}  # fmt: skip
_SWING = {"Knee": 0.12, "Ankle": 0.3, "Foot": 0.3, "Elbow": -0.08, "Wrist": -0.18, "Hand": -0.2}


def _template() -> tuple[np.ndarray, np.ndarray]:
    """``(J, 3)`` rest pose and ``(J,)`` signed swing amplitude (left +, right -)."""
    rest = np.zeros((AZURE_KINECT.n_joints, 3))
    swing = np.zeros(AZURE_KINECT.n_joints)
    for index, name in enumerate(AZURE_KINECT.joint_names):
        mirror_name = name.replace("Right", "Left")
        left, forward, up = _TEMPLATE[mirror_name]
        side = -1.0 if "Right" in name else 1.0
        rest[index] = (side * left, forward, up)
        for part, amplitude in _SWING.items():
            if name.startswith(part) and "Tip" not in name:
                swing[index] = side * amplitude
    return rest, swing


REST, SWING = _template()

Path = Callable[[float], tuple[np.ndarray, float]]
"""t (s) -> (xy position (2,), heading (rad))."""


def straight(start: tuple[float, float], velocity: tuple[float, float]) -> Path:
    """A person walking at constant velocity, facing where they walk."""
    start_xy, velocity_xy = np.array(start), np.array(velocity)
    heading = float(np.arctan2(velocity_xy[1], velocity_xy[0]))
    return lambda t: (start_xy + velocity_xy * t, heading)


def pose(xy: np.ndarray, heading: float, t: float, phase: float = 0.0) -> np.ndarray:
    """``(J, 3)`` world pose of a walking person."""
    local = REST.copy()
    local[:, 1] += SWING * np.sin(2 * np.pi * 1.8 * t + phase)
    left = np.array([-np.sin(heading), np.cos(heading), 0.0])
    forward = np.array([np.cos(heading), np.sin(heading), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    return np.array([xy[0], xy[1], 0.0]) + local @ np.stack([left, forward, up])


def camera_ring(n: int, radius: float = 4.0, height: float = 1.5) -> Calibration:
    """``n`` cameras evenly on a ring looking at the origin, with distinct clock offsets."""
    from scipy.spatial.transform import Rotation

    cameras = {}
    for index in range(n):
        angle = 2 * np.pi * index / n
        position = np.array([radius * np.cos(angle), radius * np.sin(angle), height])
        forward = -np.array([np.cos(angle), np.sin(angle), 0.0])
        right = np.cross(forward, [0.0, 0.0, 1.0])
        down = np.cross(forward, right)
        rotation = Rotation.from_matrix(np.stack([right, down, forward], axis=1))
        name = f"k{index + 1:02d}"
        cameras[name] = CameraCalibration(
            frame_id=f"{name}_depth_camera_link",
            time_offset=0.5 * index - 0.25,
            translation=position,
            rotation=rotation.as_quat(),
        )
    return Calibration(reference="k01", world_frame="world", cameras=cameras)


Modifier = Callable[[str, float, int, np.ndarray], np.ndarray | None]
"""(camera, reference time, person index, camera-frame pose) -> pose, or None to hide it."""


@dataclass
class Scene:
    """Frames of every camera in arrival order and the truth behind them."""

    calibration: Calibration
    frames: list[SkeletonGroup]
    truth: Callable[[float], np.ndarray] = field(repr=False)
    """Reference time (s) -> ``(P, J, 3)`` true world poses."""


T0 = 1000.0
"""Reference time of a scene's first instant (s), so that stamps are not trivially small."""


def render(
    paths: list[Path],
    *,
    n_cameras: int = 3,
    duration: float = 6.0,
    rate: float = 30.0,
    noise: float = 0.01,
    seed: int = 0,
    modify: Modifier | None = None,
    body_ids: Callable[[str, float, int], int] | None = None,
) -> Scene:
    """Render the people on ``paths`` through a camera ring, frames sorted by reference time."""
    rng = np.random.default_rng(seed)
    calibration = camera_ring(n_cameras)
    frames: list[tuple[float, SkeletonGroup]] = []
    for index, (name, camera) in enumerate(calibration.cameras.items()):
        to_camera = camera.extrinsics.inverse()
        phase = index / (n_cameras * rate)
        for k in range(int(duration * rate)):
            t = k / rate + phase
            t_camera = T0 + t - camera.time_offset
            stamp = round(t_camera * 1e9)
            skeletons = []
            for person, path in enumerate(paths):
                xy, heading = path(t)
                local = to_camera.apply(pose(xy, heading, t, phase=person))
                local = local + rng.normal(0.0, noise, local.shape)
                if modify is not None:
                    local = modify(name, t, person, local)
                    if local is None:
                        continue
                body = body_ids(name, t, person) if body_ids else person + 1
                skeletons.append(
                    Skeleton.from_positions(
                        local,
                        skeleton_id=body,
                        src_time_ns=stamp,
                        src_frame=camera.frame_id,
                        confidences=np.full(len(local), 0.9),
                    )
                )
            frames.append((t, SkeletonGroup(stamp, camera.frame_id, skeletons)))
    frames.sort(key=lambda item: item[0])

    def truth(t: float) -> np.ndarray:
        return np.stack([pose(*path(t - T0), t - T0, phase=p) for p, path in enumerate(paths)])

    return Scene(calibration, [frame for _, frame in frames], truth)


def run_tracker(tracker: object, frames: list[SkeletonGroup]) -> list[SkeletonGroup]:
    """Every output of a tracker fed ``frames`` in order, the final flush included."""
    outputs = [tracker.update(frame) for frame in frames]  # type: ignore[attr-defined]
    outputs.append(tracker.flush())  # type: ignore[attr-defined]
    return [group for group in outputs if group.skeletons]


def identities(outputs: list[SkeletonGroup], truth: Callable[[float], np.ndarray]) -> dict:
    """For each true person, the track ids its detections got, in time order."""
    seen: dict[int, list[int]] = {}
    for group in outputs:
        for skeleton in group.skeletons:
            true = truth(skeleton.src_time)
            distance = np.nanmean(np.linalg.norm(true - skeleton.positions, axis=2), axis=1)
            person = int(np.argmin(distance))
            assert distance[person] < 0.1, "an output does not lie on a person (or is mirrored)"
            seen.setdefault(person, []).append(skeleton.id)
    return seen


@pytest.fixture
def scenes() -> SimpleNamespace:
    """The scene helpers of this module."""
    return SimpleNamespace(
        T0=T0,
        camera_ring=camera_ring,
        identities=identities,
        pose=pose,
        render=render,
        run_tracker=run_tracker,
        straight=straight,
        crossing=[straight((-2.0, 0.25), (0.8, 0.0)), straight((2.0, -0.25), (-0.8, 0.0))],
    )
