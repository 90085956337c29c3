"""The filter's kernels stated in numpy: the readable specification of ``hiros_filter.compiled``.

The Kalman bank's predict and masked correction (``kalman_step``), the projection of the
filtered states onto the input's held link lengths (``keep_lengths``, the maths in
``hiros_filter/lengths.py``'s docstring), the slerp smoothing of the orientations with their
angular rates (``smooth_orientations``), and ``ReferenceFilter``: a ``Filter`` whose every frame
goes through these numpy forms (``filter_step`` in Kalman mode is the same steps in one call).
``test/hiros_filter`` holds the kernels to them. Shapes: ``S`` slots, ``n`` tracks of the
frame, ``J`` joints; quaternions x, y, z, w.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from hiros_core.kinematics import KinematicTree
from hiros_core.model import SkeletonRows, link_rows
from hiros_core.stacking import LayoutRows, output_skeletons
from hiros_filter.estimators import KalmanBank, _block
from hiros_filter.filter import Filter, _Running, _Tracks

__all__ = [
    "ReferenceFilter",
    "correct",
    "held_links",
    "predict",
    "process_noise",
    "project",
    "rotation_vectors",
    "slerp",
]

_SAME_LENGTH = 1e-9  # relative change of an input length that still counts as "held"
_EPS = 1e-12


def predict(bank: KalmanBank, slots: np.ndarray, dt: np.ndarray) -> None:
    """Advance each slot by its own ``dt`` seconds (the model is continuous-time).

    ``x ← F x`` and ``P ← F P Fᵀ + Q`` with ``F = [[1, dt, dt²/2], [0, 1, dt], [0, 0, 1]]``,
    written out row by row and column by column on whole blocks: numpy's batched 3×3
    products cost a call per matrix, these a few calls per frame.
    """
    index = _block(slots)
    step = dt[:, None, None]
    half_square = (0.5 * dt * dt)[:, None, None]
    Q = np.array([process_noise(round(float(s), 6), bank.q) for s in dt])
    x = bank.x[index]  # a view when the slots are one block
    x[:, 0] += step * x[:, 1] + half_square * x[:, 2]
    x[:, 1] += step * x[:, 2]
    P = bank.P[index]
    P[:, 0] += step * P[:, 1] + half_square * P[:, 2]  # F P, row by row
    P[:, 1] += step * P[:, 2]
    P[:, :, 0] += step * P[:, :, 1] + half_square * P[:, :, 2]  # (F P) Fᵀ, column by column
    P[:, :, 1] += step * P[:, :, 2]
    P += Q[..., None] * bank.scale[index][:, None, None, :]
    if not isinstance(index, slice):
        bank.x[index] = x
        bank.P[index] = P


def correct(bank: KalmanBank, slots: np.ndarray, mask: np.ndarray, positions: np.ndarray) -> None:
    """Correct the (slot, joint) pairs where ``mask`` ``(n, J)`` is set (H = [1, 0, 0]).

    ``K = P[:, 0] / (P[0, 0] + r)``, ``x += K ν``, ``P -= K P[0, :]`` with ``ν`` the innovation
    of ``positions`` ``(n, J, 3)`` (ignored where the mask is clear); the adaptive scale is
    smoothed towards ``|ν|² / (3 (P[0, 0] + r))`` within ``[1, max_noise_scale]``. Every joint
    of the slots is computed and the masked ones kept.
    """
    index = _block(slots)
    P = bank.P[index]  # (n, 3, 3, J), a view when the slots are one block
    x = bank.x[index]
    variance = P[:, 0, 0] + bank.r  # (n, J)
    everywhere = mask.all()
    with np.errstate(invalid="ignore", over="ignore"):
        gain = P[:, :, 0] / variance[:, None]  # (n, 3, J)
        innovation = positions.transpose(0, 2, 1) - x[:, 0]  # (n, 3 axes, J)
        if bank.max_noise_scale > 1.0:
            surprise = np.sum(innovation**2, axis=1) / (3.0 * variance)
            scale = bank.scale[index]
            smoothed = np.clip(
                scale + bank.adaptation_rate * (surprise - scale), 1.0, bank.max_noise_scale
            )
            bank.scale[index] = smoothed if everywhere else np.where(mask, smoothed, scale)
        x_step = gain[:, :, None] * innovation[:, None]
        P_step = gain[:, :, None] * P[:, None, 0]
    if everywhere:
        x += x_step
        P -= P_step
    else:
        keep = mask[:, None, None]
        x += np.where(keep, x_step, 0.0)
        P -= np.where(keep, P_step, 0.0)
    if not isinstance(index, slice):
        bank.x[index] = x
        bank.P[index] = P


@lru_cache(maxsize=256)
def process_noise(dt: float, spectral_density: float) -> np.ndarray:
    """Q of the white-jerk model for one ``dt`` (µs-rounded, cached: frames repeat their dt).

    filterpy's ``Q_continuous_white_noise(dim=3, dt, spectral_density)``, term for term (a
    test checks it), without its per-call ``block_diag``: a frame's dt rarely repeats exactly.
    """
    return (
        np.array(
            [
                [(dt**5) / 20.0, (dt**4) / 8.0, (dt**3) / 6.0],
                [(dt**4) / 8.0, (dt**3) / 3.0, (dt**2) / 2.0],
                [(dt**3) / 6.0, (dt**2) / 2.0, dt],
            ]
        )
        * spectral_density
    )


def slerp(start: np.ndarray, end: np.ndarray, fraction: float | np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` a ``fraction`` of the way from ``start`` to ``end`` on SO(3).

    Takes the short way (``end`` is sign-flipped into ``start``'s hemisphere, since q and -q
    are the same rotation) and falls back to normalised linear interpolation for tiny angles.
    """
    fraction = np.asarray(fraction, dtype=float)[..., None]
    dot = np.sum(start * end, axis=-1, keepdims=True)
    end = np.where(dot < 0, -end, end)
    angle = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))
    sin_angle = np.sin(angle)
    small = sin_angle < 1e-6
    safe = np.where(small, 1.0, sin_angle)
    weight_start = np.where(small, 1.0 - fraction, np.sin((1.0 - fraction) * angle) / safe)
    weight_end = np.where(small, fraction, np.sin(fraction * angle) / safe)
    result = weight_start * start + weight_end * end
    return result / np.linalg.norm(result, axis=-1, keepdims=True)


def rotation_vectors(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """``(..., 3)`` rotation vectors (axis × angle, world frame) turning ``start`` into ``end``.

    The relative rotation is ``end ⊗ start⁻¹``; its vector part over ``sin(θ/2)`` is the
    axis, taken the short way (w >= 0).
    """
    x0, y0, z0, w0 = np.moveaxis(start, -1, 0)
    x1, y1, z1, w1 = np.moveaxis(end, -1, 0)
    # end ⊗ conj(start)
    w = w1 * w0 + x1 * x0 + y1 * y0 + z1 * z0
    vector = np.stack(
        [
            x1 * w0 - w1 * x0 - y1 * z0 + z1 * y0,
            y1 * w0 - w1 * y0 - z1 * x0 + x1 * z0,
            z1 * w0 - w1 * z0 - x1 * y0 + y1 * x0,
        ],
        axis=-1,
    )
    sign = np.where(w < 0, -1.0, 1.0)[..., None]
    vector = vector * sign
    sine = np.linalg.norm(vector, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(sine, np.abs(w)[..., None])
    scale = np.where(sine > 1e-12, angle / np.where(sine > 1e-12, sine, 1.0), 2.0)
    return vector * scale


def held_links(
    lengths: np.ndarray, previous: np.ndarray, tolerance: float = _SAME_LENGTH
) -> np.ndarray:
    """``(n, J)`` True where a link's input length equals the previous frame's (both known)."""
    with np.errstate(invalid="ignore"):
        return np.abs(lengths - previous) <= tolerance * lengths


def project(
    tree: KinematicTree,
    states: tuple[np.ndarray, np.ndarray, np.ndarray],
    lengths: np.ndarray,
    held: np.ndarray,
    present: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Filtered ``(n, J, 3)`` states with every ``held`` link at its length (module doc).

    Args:
        states: the filter's positions, velocities and accelerations, ``(n, J, 3)`` each.
        lengths: ``(n, J)`` length of the link ending at each joint (used where held).
        held: ``(n, J)`` links to hold; links with a non-finite end are skipped.
        present: ``(n, J)`` joints that are output (their mean is kept).

    """
    positions, velocities, accelerations = states
    parent = np.maximum(tree.parents, 0)
    vectors = positions - positions[:, parent]
    norm = np.sqrt(np.add.reduce(vectors * vectors, axis=-1))
    with np.errstate(invalid="ignore"):
        hold = held & (norm > _EPS)
    safe = np.where(hold, norm, 1.0)[..., None]
    unit = vectors / safe
    length = np.where(hold, lengths, 0.0)[..., None]
    keep = hold[..., None]
    moved = np.where(keep, unit * length - vectors, 0.0)

    relative_velocity = velocities - velocities[:, parent]
    along = np.add.reduce(relative_velocity * unit, axis=-1)[..., None]
    velocity_fix = np.where(keep, -along * unit, 0.0)

    perpendicular = relative_velocity - along * unit
    centripetal = -np.add.reduce(perpendicular * perpendicular, axis=-1)[..., None] / np.where(
        keep, length, 1.0
    )
    relative_acceleration = accelerations - accelerations[:, parent]
    along_acceleration = np.add.reduce(relative_acceleration * unit, axis=-1)[..., None]
    acceleration_fix = np.where(keep, (centripetal - along_acceleration) * unit, 0.0)

    # Each correction moves its link's whole subtree; then the mean is put back. All three
    # quantities at once: (n, J, 9) through one product with the subtree matrix.
    fixes = np.concatenate([moved, velocity_fix, acceleration_fix], axis=-1)
    shifts = tree.subtree_t @ fixes
    weight = present.astype(float)
    count = np.maximum(weight.sum(axis=1), 1.0)[:, None, None]
    shifts -= (weight[..., None] * shifts).sum(axis=1, keepdims=True) / count
    return (
        positions + shifts[..., 0:3],
        velocities + shifts[..., 3:6],
        accelerations + shifts[..., 6:9],
    )


class ReferenceFilter(Filter):
    """A ``Filter`` whose frames go through the numpy statements of its kernels."""

    def _step(self, tracks: _Tracks, stack: LayoutRows, steps: list[_Running]) -> list:
        """``Filter._step`` without the one-call Kalman kernel: ``_step_rows`` in either mode."""
        skeletons = [step.skeleton for step in steps]
        indices = [step.row for step in steps]
        markers, present = stack.take(indices)
        rows = np.array([tracks.slots[s.id] for s in skeletons], dtype=np.int64)
        stamps = np.array([s.src_time_ns for s in skeletons], dtype=np.int64)
        self._step_rows(tracks, rows, stamps, markers, present)
        links, link_present = link_rows(markers, present, tracks.layout)
        return output_skeletons(
            skeletons,
            [s.id for s in skeletons],
            SkeletonRows(markers, present, links, link_present, stack.input_boxes(indices)),
        )

    def _kalman_step(
        self,
        tracks: _Tracks,
        rows: np.ndarray,
        dt: np.ndarray,
        mask: np.ndarray,
        measured: np.ndarray,
    ) -> None:
        predict(tracks.kalman, rows, dt)
        correct(tracks.kalman, rows, mask, measured)

    def _keep_lengths(
        self,
        tracks: _Tracks,
        rows: np.ndarray,
        states: tuple[np.ndarray, np.ndarray, np.ndarray],
        measured: np.ndarray,
        present: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        lengths = tracks.keeper.lengths(np.where(present[..., None], measured, np.nan))
        held = held_links(lengths, tracks.last_lengths[rows])
        tracks.last_lengths[rows] = lengths
        if held.any():
            return project(tracks.keeper.tree, states, lengths, held, present)
        return states

    def _smooth_orientations(
        self,
        tracks: _Tracks,
        rows: np.ndarray,
        markers: np.ndarray,
        present: np.ndarray,
        dt: np.ndarray | None,
    ) -> None:
        """Slerp-smooth the orientations of ``markers`` ``(n, J, 20)`` in place (and the state).

        Towards each new unit quaternion by ``1 - exp(-2π f_c dt)``; the angular velocity is
        the rotation vector between consecutive outputs over dt, the acceleration its change;
        a joint without a previous orientation starts on its own, without rates.
        """
        quaternions = markers[..., 4:8]
        norms = np.sqrt(np.add.reduce(quaternions * quaternions, axis=-1))  # as np.linalg.norm
        valid = present & np.isfinite(norms) & (norms > 0.5)
        unit = quaternions / np.where(valid, norms, 1.0)[..., None]
        previous = tracks.quaternions[rows]
        angular_velocities = tracks.angular_velocities[rows]
        angular_accelerations = tracks.angular_accelerations[rows]
        fresh = valid
        smoothed = previous
        if dt is not None:
            carry = valid & np.isfinite(previous).all(axis=-1)
            if carry.any():
                fresh = valid & ~carry
                cutoff = self.params.orientation_cutoff_frequency
                weight = 1.0 - np.exp(-2.0 * np.pi * cutoff * dt)
                with np.errstate(invalid="ignore", divide="ignore"):
                    turned = slerp(previous, unit, weight[:, None])
                    step = dt[:, None, None]
                    velocity = rotation_vectors(previous, turned) / step
                    acceleration = np.where(
                        np.isfinite(angular_velocities),
                        (velocity - angular_velocities) / step,
                        0.0,
                    )
                keep = carry[..., None]
                smoothed = np.where(keep, turned, previous)
                angular_accelerations = np.where(keep, acceleration, angular_accelerations)
                angular_velocities = np.where(keep, velocity, angular_velocities)
        if fresh.any():
            keep = fresh[..., None]
            smoothed = np.where(keep, unit, smoothed)
            angular_velocities = np.where(keep, np.nan, angular_velocities)
            angular_accelerations = np.where(keep, np.nan, angular_accelerations)
        tracks.quaternions[rows] = smoothed
        tracks.angular_velocities[rows] = angular_velocities
        tracks.angular_accelerations[rows] = angular_accelerations
        keep = valid[..., None]
        np.copyto(markers[..., 4:8], smoothed, where=keep)
        np.copyto(markers[..., 11:14], angular_velocities, where=keep)
        np.copyto(markers[..., 17:20], angular_accelerations, where=keep)
