"""Rigid transforms and quaternion helpers on ``scipy.spatial.transform``.

Quaternions are x, y, z, w (the message and scipy order). Extrinsics follow DESIGN.md:
``p_world = R p_camera + t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.model import Skeleton

__all__ = ["RigidTransform", "normalize_quaternions"]


def normalize_quaternions(quaternions: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)``; rows with NaN or zero norm stay NaN."""
    norm = np.linalg.norm(quaternions, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = quaternions / norm
    out[~np.isfinite(out).all(axis=-1)] = np.nan
    return out


@dataclass(frozen=True)
class RigidTransform:
    """``p_out = rotation.apply(p_in) + translation``.

    Attributes:
        rotation: a scipy ``Rotation``.
        translation: ``(3,)`` metres.

    """

    rotation: Rotation
    translation: np.ndarray

    @classmethod
    def identity(cls) -> RigidTransform:
        """The transform that changes nothing."""
        return cls(Rotation.identity(), np.zeros(3))

    @classmethod
    def from_quaternion(
        cls, quaternion_xyzw: np.ndarray, translation: np.ndarray
    ) -> RigidTransform:
        """From a quaternion x, y, z, w and a translation."""
        return cls(Rotation.from_quat(quaternion_xyzw), np.asarray(translation, dtype=float))

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> RigidTransform:
        """From a 4x4 homogeneous matrix."""
        return cls(Rotation.from_matrix(matrix[:3, :3]), np.asarray(matrix[:3, 3], dtype=float))

    @property
    def quaternion(self) -> np.ndarray:
        """``(4,)`` rotation as x, y, z, w with w >= 0."""
        quat = self.rotation.as_quat()
        return -quat if quat[3] < 0 else quat

    def as_matrix(self) -> np.ndarray:
        """4x4 homogeneous matrix."""
        matrix = np.eye(4)
        matrix[:3, :3] = self.rotation.as_matrix()
        matrix[:3, 3] = self.translation
        return matrix

    def inverse(self) -> RigidTransform:
        """The transform back."""
        inv = self.rotation.inv()
        return RigidTransform(inv, -inv.apply(self.translation))

    def __matmul__(self, other: RigidTransform) -> RigidTransform:
        """Composition: ``(a @ b).apply(p) == a.apply(b.apply(p))``."""
        return RigidTransform(
            self.rotation * other.rotation,
            self.rotation.apply(other.translation) + self.translation,
        )

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform points ``(..., 3)``; NaN rows stay NaN."""
        points = np.asarray(points, dtype=float)
        matrix = self.rotation.as_matrix()
        return points @ matrix.T + self.translation

    def rotate(self, vectors: np.ndarray) -> np.ndarray:
        """Rotate free vectors ``(..., 3)`` (velocities, accelerations) without translating."""
        return np.asarray(vectors, dtype=float) @ self.rotation.as_matrix().T

    def rotate_quaternions(self, quaternions: np.ndarray) -> np.ndarray:
        """Left-multiply orientations ``(N, 4)`` by the rotation; NaN rows stay NaN."""
        out = np.full_like(quaternions, np.nan, dtype=float)
        valid = np.isfinite(quaternions).all(axis=1) & (np.linalg.norm(quaternions, axis=1) > 0)
        if valid.any():
            out[valid] = (self.rotation * Rotation.from_quat(quaternions[valid])).as_quat()
        return out

    def apply_to_skeleton(self, skeleton: Skeleton) -> Skeleton:
        """A copy of the skeleton with every pose, twist and accel moved by this transform."""
        out = skeleton.copy()
        for rows in (out.markers, out.links):
            rows[:, 1:4] = self.apply(rows[:, 1:4])
            rows[:, 4:8] = self.rotate_quaternions(rows[:, 4:8])
            for start in (8, 11, 14, 17):
                rows[:, start : start + 3] = self.rotate(rows[:, start : start + 3])
        box = out.bounding_box
        box[0:3] = self.apply(box[0:3])
        box[3:7] = self.rotate_quaternions(box[None, 3:7])[0]
        return out
