"""Keep the optimizer's limb lengths in the filter's output, with consistent derivatives.

A linear filter smooths each coordinate on its own, so a link that turns comes out shorter
(the average of two directions is shorter than either) and a link that speeds up or slows down
comes out longer or shorter: the lengths the optimizer fixed vary again by a few percent.
Smoothing is linear, so filtering the joint positions and then taking differences is the same
as filtering the link vectors; rescaling each filtered link vector back to its length therefore
keeps the smoothed *directions* (and so the joint angles) and only restores the lengths. The
skeleton is rebuilt from the root outwards (every joint moves with the corrections of the links
above it) and translated so that the mean of its joints stays where the filter put it (the
best translation in the least-squares sense).

Derivatives follow the same constraint. A link of constant length ``L`` along the unit vector
``u`` has a relative velocity ``dv`` perpendicular to ``u`` and a relative acceleration whose
component along ``u`` is the centripetal ``-|dv|² / L``; the along-link parts of the filtered
relative velocities and accelerations are replaced by those values and the whole body is
rebuilt in the same way (mean kept).

Which links to hold is read from the input itself: a link whose length is the same (to 1e-9
relative) in two consecutive input frames of a track is one the optimizer constrains; links
it leaves free (and people it has not calibrated yet) vary from frame to frame and are left as
the filter made them.
"""

from __future__ import annotations

import numpy as np

from hiros_optimizer.kinematics import KinematicTree

__all__ = ["LengthKeeper", "held_links"]

_SAME_LENGTH = 1e-9  # relative change of an input length that still counts as "held"
_EPS = 1e-12


def held_links(
    lengths: np.ndarray, previous: np.ndarray, tolerance: float = _SAME_LENGTH
) -> np.ndarray:
    """``(n, J)`` True where a link's input length equals the previous frame's (both known)."""
    with np.errstate(invalid="ignore"):
        return np.abs(lengths - previous) <= tolerance * lengths


class LengthKeeper:
    """Projection of filtered positions, velocities and accelerations onto fixed lengths."""

    def __init__(self, tree: KinematicTree) -> None:
        self.tree = tree
        self._parent = np.maximum(tree.parents, 0)

    def lengths(self, positions: np.ndarray) -> np.ndarray:
        """``(n, J)`` link lengths of ``(n, J, 3)`` positions (NaN for roots, missing ends)."""
        vectors = positions - positions[:, self._parent]
        lengths = np.sqrt(np.add.reduce(vectors * vectors, axis=-1))
        lengths[:, ~self.tree.has_parent] = np.nan
        return lengths

    def project(
        self,
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
        parent = self._parent
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
        shifts = self.tree.subtree_t @ fixes
        weight = present.astype(float)
        count = np.maximum(weight.sum(axis=1), 1.0)[:, None, None]
        shifts -= (weight[..., None] * shifts).sum(axis=1, keepdims=True) / count
        return (
            positions + shifts[..., 0:3],
            velocities + shifts[..., 3:6],
            accelerations + shifts[..., 6:9],
        )
