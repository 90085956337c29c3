"""Rigid transforms and quaternion helpers on ``scipy.spatial.transform``.

Quaternions are x, y, z, w (the message and scipy order). Extrinsics follow DESIGN.md:
``p_world = R p_camera + t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.model import Skeleton

__all__ = ["RigidTransform", "kabsch", "kabsch_batch", "normalize_quaternions"]


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


def kabsch(
    target: np.ndarray, source: np.ndarray, weights: np.ndarray | None = None
) -> RigidTransform:
    """The rigid transform moving ``source (N, 3)`` onto ``target (N, 3)`` (weighted SVD).

    Kabsch (1976) / Umeyama (1991) without scale: minimises ``sum w |R s + t - p|^2``.
    """
    rotation, translation = kabsch_batch(
        target[None], source[None], None if weights is None else weights[None]
    )
    return RigidTransform(Rotation.from_matrix(rotation[0]), translation[0])


def kabsch_batch(
    target: np.ndarray, source: np.ndarray, weights: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Kabsch for ``H`` problems at once: ``(H, N, 3)`` points -> ``(H, 3, 3)``, ``(H, 3)``.

    One batched SVD instead of a loop: RANSAC scores hundreds of minimal samples, and the
    simulator's noise fit one transform per frame. Never returns a reflection.
    """
    if weights is None:
        weights = np.ones(target.shape[:2])
    w = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
    mean_t = (w[..., None] * target).sum(axis=1)
    mean_s = (w[..., None] * source).sum(axis=1)
    cov = np.einsum("hn,hni,hnj->hij", w, target - mean_t[:, None], source - mean_s[:, None])
    u, _, vt = np.linalg.svd(cov)
    sign = np.sign(np.linalg.det(u @ vt))
    sign[sign == 0] = 1.0
    u[:, :, 2] *= sign[:, None]
    rotation = u @ vt
    translation = mean_t - np.einsum("hij,hj->hi", rotation, mean_s)
    return rotation, translation
