"""Small synthetic multi-camera scenes for the calibration tests (no simulator needed).

People are forward-kinematics skeletons with fixed limb lengths whose joint angles and root
path are sums of sinusoids, so the motion is an exact function of reference time and a camera
sampling it on its own clock gives exactly known offsets. Cameras stand on a circle looking at
the centre (x right, y down, z forward, as the Azure Kinect depth frame); a camera that sees a
person from behind reports left and right swapped, as the body-tracking SDK does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.geometry import RigidTransform
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup

# parent -> child offsets in the body frame (x right, y forward, z up), metres
_OFFSETS = np.array([
    [0, 0, 0], [0, 0, 0.2], [0, 0, 0.2], [0, 0, 0.2],
    [-0.05, 0, 0.15], [-0.15, 0, 0], [0, 0, -0.28], [0, 0, -0.25],
    [0, 0, -0.08], [0, 0, -0.07], [0, 0.04, -0.06],
    [0.05, 0, 0.15], [0.15, 0, 0], [0, 0, -0.28], [0, 0, -0.25],
    [0, 0, -0.08], [0, 0, -0.07], [0, 0.04, -0.06],
    [-0.1, 0, -0.05], [0, 0, -0.42], [0, 0, -0.42], [0, 0.12, -0.06],
    [0.1, 0, -0.05], [0, 0, -0.42], [0, 0, -0.42], [0, 0.12, -0.06],
    [0, 0, 0.12], [0, 0.1, 0], [-0.03, 0.08, 0.04], [-0.08, 0, 0.02],
    [0.03, 0.08, 0.04], [0.08, 0, 0.02],
])  # fmt: skip
# joints that rotate, and how much (rad amplitude of their angle signals)
_MOVING = {1: 0.15, 2: 0.15, 3: 0.3, 5: 1.0, 6: 0.9, 12: 1.0, 13: 0.9, 18: 0.6, 19: 0.7,
           22: 0.6, 23: 0.7, 7: 0.4, 14: 0.4}  # fmt: skip


@dataclass
class Person:
    """One synthetic person: sinusoid coefficients of root path, heading and joint angles."""

    seed: int
    scale: float = 1.0
    still: bool = False
    rng: np.random.Generator = field(init=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        r = self.rng
        self.path = [(r.uniform(0.03, 0.15, 3), r.uniform(0.2, 0.7, 3), r.uniform(0, 6.3, 3))
                     for _ in range(2)]  # fmt: skip
        self.center = r.uniform(-0.7, 0.7, 2)
        self.heading = (r.uniform(0.02, 0.08, 2), r.uniform(1.0, 2.5, 2), r.uniform(0, 6.3, 2))
        self.angles = {
            j: (
                r.uniform(0.2, 1.5, (3, 3)),
                a * r.uniform(0.2, 0.6, (3, 3)),
                r.uniform(0, 6.3, (3, 3)),
            )
            for j, a in _MOVING.items()
        }

    def positions(self, t: np.ndarray) -> np.ndarray:
        """``(T, 32, 3)`` world positions (z up) at reference times ``t``."""
        t = np.asarray(t, dtype=float)
        if self.still:
            t = np.zeros_like(t)
        root = np.zeros((len(t), 3))
        for axis, (f, a, p) in enumerate(self.path):
            root[:, axis] = self.center[axis] + (
                a[:, None] * np.sin(2 * np.pi * f[:, None] * t + p[:, None])
            ).sum(0)
        root[:, 2] = 1.0 * self.scale
        f, a, p = self.heading
        yaw = (a[:, None] * np.sin(2 * np.pi * f[:, None] * t + p[:, None])).sum(0)
        rotations = [Rotation.from_euler("z", yaw[:, None])]
        out = np.zeros((len(t), 32, 3))
        out[:, 0] = root
        for joint in range(1, 32):
            parent = AZURE_KINECT.parents[joint]
            out[:, joint] = out[:, parent] + rotations[parent].apply(_OFFSETS[joint] * self.scale)
            if joint in self.angles:
                f, a, p = self.angles[joint]
                rotvec = (
                    (a[..., None] * np.sin(2 * np.pi * f[..., None] * t + p[..., None])).sum(1).T
                )
                rotations.append(rotations[parent] * Rotation.from_rotvec(rotvec))
            else:
                rotations.append(rotations[parent])
        return out

    def facing(self, t: np.ndarray) -> np.ndarray:
        """``(T, 3)`` the direction the person faces (body +y) in the world."""
        t = np.zeros_like(t) if self.still else np.asarray(t, dtype=float)
        f, a, p = self.heading
        yaw = (a[:, None] * np.sin(2 * np.pi * f[:, None] * t + p[:, None])).sum(0)
        return np.stack([-np.sin(yaw), np.cos(yaw), np.zeros_like(yaw)], axis=1)


def look_at(position: np.ndarray, target: np.ndarray) -> RigidTransform:
    """Camera -> world for a camera at ``position`` looking at ``target`` (x right, y down)."""
    forward = target - position
    forward = forward / np.linalg.norm(forward)
    down = np.array([0.0, 0.0, -1.0])
    down = down - forward * (down @ forward)
    down /= np.linalg.norm(down)
    right = np.cross(down, forward)
    return RigidTransform(Rotation.from_matrix(np.stack([right, down, forward], axis=1)), position)


@dataclass
class Scene:
    """What a synthetic run produces: per-camera groups and the true calibration."""

    camera_groups: dict[str, list[SkeletonGroup]]
    truth: Calibration
    people: list[Person]


def make_scene(
    *,
    angles_deg: tuple[float, ...] = (0.0, 180.0, 90.0),
    n_people: int = 1,
    duration: float = 20.0,
    rate: float = 30.0,
    offsets: tuple[float, ...] = (0.0, 0.4123, -0.2871),
    drifts: tuple[float, ...] = (0.0, 0.0, 0.0),
    noise: float = 0.0,
    drop: float = 0.0,
    mirror_behind: bool = True,
    still: bool = False,
    seed: int = 0,
    clock_origin: tuple[float, ...] = (100.0, 5000.0, 12.0),
    moves: dict[int, tuple[float, RigidTransform]] | None = None,
) -> Scene:
    """Cameras on a 3.5 m circle at the given angles, each on its own clock.

    Camera i's clock starts at ``clock_origin[i]`` (so clocks disagree by much more than the
    frame period) and ``offsets[i]`` is the extra shift of its motion: ``t_ref = t_cam +
    time_offset + drift (t_cam - e)`` with ``time_offset = clock_origin[0] - clock_origin[i] +
    offsets[i]`` and ``e = clock_origin[i]``; camera 0 (offset 0) is the reference. The
    truth's world frame is the scene's world frame. ``moves`` maps a camera index to
    ``(reference time, world-frame transform)``: from then on the camera's pose is the
    transform applied to its original pose (the truth keeps the original pose).
    """
    rng = np.random.default_rng(seed + 1000)
    people = [Person(seed * 10 + i, scale=1.0 + 0.08 * i, still=still) for i in range(n_people)]
    cameras: dict[str, list[SkeletonGroup]] = {}
    truth = Calibration(reference="cam0", world_frame="world")
    for index, angle in enumerate(angles_deg):
        name = f"cam{index}"
        rad = np.radians(angle)
        position = np.array([3.5 * np.cos(rad), 3.5 * np.sin(rad), 1.4 + 0.1 * index])
        pose = look_at(position, np.array([0.0, 0.0, 1.0]))
        origin = clock_origin[index]
        # camera frames start at its clock origin, sampled slightly off the nominal rate
        t_cam = origin + rng.uniform(0, 1 / rate) + np.arange(int(duration * rate)) / rate
        time_offset = clock_origin[0] - origin + offsets[index]
        t_ref = t_cam + time_offset + drifts[index] * (t_cam - origin)
        keep = rng.random(len(t_cam)) >= drop
        t_cam, t_ref = t_cam[keep], t_ref[keep]
        frame = f"{name}_depth_camera_link"
        inverse = pose.inverse()
        per_person = []
        move = (moves or {}).get(index)
        for person in people:
            world = person.positions(t_ref)
            local = inverse.apply(world)
            if move is not None:
                after = t_ref >= move[0]
                local[after] = (move[1] @ pose).inverse().apply(world[after])
            local = local + rng.normal(0, noise, local.shape) if noise else local
            behind = (person.facing(t_ref) * (position - world[:, 0])).sum(1) < 0
            if mirror_behind:
                local[behind] = local[behind][:, AZURE_KINECT.mirror]
            per_person.append(local)
        groups = []
        for k, stamp in enumerate(t_cam):
            stamp_ns = round(stamp * 1e9)
            skeletons = [
                Skeleton.from_positions(
                    per_person[p][k],
                    AZURE_KINECT,
                    skeleton_id=p + 1,
                    src_time_ns=stamp_ns,
                    src_frame=frame,
                    confidences=np.full(32, 3.0),
                )
                for p in range(n_people)
            ]
            groups.append(SkeletonGroup(stamp_ns, frame, skeletons))
        cameras[name] = groups
        truth.cameras[name] = CameraCalibration(
            frame_id=frame,
            time_offset=time_offset,
            drift=drifts[index],
            drift_epoch=origin,
            translation=pose.translation,
            rotation=pose.quaternion,
        )
    return Scene(cameras, truth, people)
