"""The optimizer's kernels stated in numpy: the readable specification of ``hiros_optimizer``.

``fit_fixed_lengths`` is ``hiros_optimizer.kinematics.fit_fixed_lengths`` (the compiled fit of
``hiros_optimizer.compiled``); ``ReferenceMemory`` is a ``Memory`` whose ``learn`` and ``fit``
are the numpy forms of the frame kernels (``learn_frame``, ``fit_frame_links``), computing the
same numbers in the same order; ``unusable_rows`` is ``stacking._unusable_rows``. The tests in
``test/hiros_optimizer`` hold the kernels equal to them. Shapes: ``P`` people, ``J`` joints.
"""

from __future__ import annotations

import numpy as np

from hiros_core.kinematics import KinematicTree, link_lengths
from hiros_core.model import link_rows
from hiros_optimizer.memory import FitSettings, Memory, _weights

__all__ = ["ReferenceMemory", "fit_fixed_lengths", "unusable_rows"]

_EPS = 1e-12
_MIN_VELOCITY_DT = 1e-3  # s; as ``hiros_optimizer.compiled``


def unusable_rows(markers: np.ndarray, present: np.ndarray) -> np.ndarray:
    """``(P,)`` True where a present joint's position (columns 1-3) is not finite."""
    return (present & ~np.isfinite(markers[..., 1:4]).all(axis=-1)).any(axis=-1)


def _norm(vectors: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(vectors, axis=-1)``: the same arithmetic without its wrapper."""
    return np.sqrt(np.add.reduce(vectors * vectors, axis=-1))


def _initial_vectors(
    tree: KinematicTree,
    targets: np.ndarray,
    weights: np.ndarray,
    lengths: np.ndarray,
    fallback_vectors: np.ndarray | None,
) -> np.ndarray:
    """Start of the fit: the measurement projected onto the length spheres, root outward.

    Each joint is placed at its length from its (already placed) parent, towards its target;
    a joint with no weight aims at the weighted centroid of the targets below it, else keeps
    the fallback vector (last frame), else points straight down.
    """
    below = weights @ tree.subtree.T  # (P, J) weight at and below each joint
    centroid = tree.subtree @ (weights[..., None] * targets)
    aim = np.divide(centroid, below[..., None], out=targets.copy(), where=below[..., None] > 0)
    aim = np.where((weights > 0)[..., None], targets, aim)
    has_aim = below > 0
    constrained = np.isfinite(lengths)
    default = np.array([0.0, 0.0, -1.0])
    vectors = np.zeros_like(targets)
    positions = np.zeros_like(targets)
    any_missing = not has_aim.all()  # usually every joint has an aim: skip those branches
    for depth, level in enumerate(tree.levels):
        base = 0.0 if depth == 0 else positions[:, tree.parents[level]]
        vector = aim[:, level] - base
        if any_missing:
            missing = ~has_aim[:, level]
            if fallback_vectors is not None:
                fallback = fallback_vectors[:, level]
                usable = missing & np.isfinite(fallback).all(axis=-1)
                vector[usable] = fallback[usable]
                missing &= ~usable
            vector[missing] = default if depth > 0 else 0.0
        norm = _norm(vector)[..., None]
        tiny = (norm < _EPS)[..., 0] & constrained[:, level]
        if tiny.any():
            vector[tiny] = default
            norm[tiny] = 1.0
        on_sphere = lengths[:, level, None] * vector / np.where(norm < _EPS, 1.0, norm)
        vector = np.where(constrained[:, level, None], on_sphere, vector)
        vectors[:, level] = vector
        positions[:, level] = base + vector
    return vectors


def fit_fixed_lengths(
    tree: KinematicTree,
    measured: np.ndarray,
    weights: np.ndarray,
    lengths: np.ndarray,
    *,
    prior: np.ndarray | None = None,
    prior_weight: float = 0.0,
    fallback_vectors: np.ndarray | None = None,
    sweeps: int = 1,
    refinements: int = 2,
) -> tuple[np.ndarray, np.ndarray]:
    """``kinematics.fit_fixed_lengths`` in numpy (the same arguments and results).

    The targets are the weighted means of the measurements and the prior; block-coordinate
    sweeps root -> leaves start the fit, Gauss-Newton steps on the length spheres refine it
    (``hiros_optimizer/kinematics.py``'s docstring states the maths).
    """
    weights = np.where(np.isfinite(measured).all(axis=-1), np.clip(weights, 0.0, None), 0.0)
    weights = np.nan_to_num(weights)
    targets = np.nan_to_num(measured) * weights[..., None]
    total = weights.copy()
    if prior is not None and prior_weight > 0:
        has_prior = np.isfinite(prior).all(axis=-1)
        targets += np.where(has_prior[..., None], prior_weight * np.nan_to_num(prior), 0.0)
        total += prior_weight * has_prior
    targets = np.divide(
        targets, total[..., None], out=np.zeros_like(targets), where=total[..., None] > 0
    )

    vectors = _initial_vectors(tree, targets, total, lengths, fallback_vectors)
    positions = tree.subtree_t @ vectors
    problem = (tree, targets, total, lengths)
    positions, vectors = _coordinate_sweeps(
        *problem, positions=positions, vectors=vectors, sweeps=sweeps
    )
    return _gauss_newton(*problem, positions=positions, vectors=vectors, refinements=refinements)


def _coordinate_sweeps(
    tree: KinematicTree,
    targets: np.ndarray,
    total: np.ndarray,
    lengths: np.ndarray,
    *,
    positions: np.ndarray,
    vectors: np.ndarray,
    sweeps: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact block updates, one depth level at a time (module docstring)."""
    subtree_weight = total @ tree.subtree.T  # (P, J): weight below (and at) each joint
    constrained = np.isfinite(lengths)
    for _ in range(sweeps):
        for level, rows, below in zip(
            tree.levels, tree.level_subtrees, tree.level_below, strict=True
        ):
            residual = total[..., None] * (targets - positions)
            w_sub = subtree_weight[:, level, None]
            old = vectors[:, level]
            pull = rows @ residual + w_sub * old
            norm = _norm(pull)[..., None]
            on_sphere = lengths[:, level, None] * pull / np.where(norm > _EPS, norm, 1.0)
            free = pull / np.where(w_sub > _EPS, w_sub, 1.0)
            new = np.where(constrained[:, level, None], on_sphere, free)
            # No weight anywhere below this link: nothing to fit, keep the previous vector.
            new = np.where((w_sub > _EPS) & (norm > _EPS), new, old)
            vectors[:, level] = new
            positions += below @ (new - old)
    return positions, vectors


def _tangent_basis(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to each unit ``(..., 3)`` direction and to each other."""
    helper = np.where(
        (np.abs(directions[..., 0]) < 0.9)[..., None], np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    )
    first = _cross(directions, helper)
    first /= _norm(first)[..., None]
    return first, _cross(directions, first)


_NEXT = np.array([1, 2, 0])
_AFTER = np.array([2, 0, 1])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of ``(..., 3)`` vectors: the same products, as four gathers."""
    return a[..., _NEXT] * b[..., _AFTER] - a[..., _AFTER] * b[..., _NEXT]


def _objective(positions: np.ndarray, targets: np.ndarray, total: np.ndarray) -> np.ndarray:
    return np.einsum("pj,pj->p", total, ((positions - targets) ** 2).sum(axis=-1))


def _gauss_newton(
    tree: KinematicTree,
    targets: np.ndarray,
    total: np.ndarray,
    lengths: np.ndarray,
    *,
    positions: np.ndarray,
    vectors: np.ndarray,
    refinements: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton on the link vectors with a retraction onto the length spheres."""
    if refinements <= 0:
        return positions, vectors
    n_people, n_joints, _ = vectors.shape
    n_params = 3 * n_joints
    constrained = np.isfinite(lengths)
    scale = np.where(constrained, lengths, 1.0)
    shared = (tree.subtree * total[:, None, :]) @ tree.subtree_t
    joint_of = np.arange(n_params) // 3  # parameter -> its link (3 per link)
    # A calibrated link has only 2 tangent parameters: its third (zero) column gets a unit
    # diagonal so the system stays regular; a tiny Levenberg term covers weightless subtrees.
    padding = np.zeros((n_people, n_joints, 3))
    padding[..., 2] = constrained
    padding = padding.reshape(n_people, n_params) + 1e-9
    # Those padded parameters are decoupled (zero rows and columns, zero gradient: their step
    # is 0), so when every person has the same calibrated links the system is solved without
    # them: a third smaller, a third as costly to factor, the same steps.
    real = padding < 1.0
    same = (real == real[0]).all() and not real[0].all()
    keep = np.flatnonzero(real[0]) if same else None
    if keep is not None:
        joint_of = joint_of[keep]
        padding = padding[:, keep]
    shared = shared[:, joint_of[:, None], joint_of]  # the link weights of every parameter pair
    diagonal = np.arange(len(joint_of))
    identity = np.eye(3)
    cost = _objective(positions, targets, total)
    for _ in range(refinements):
        first, second = _tangent_basis(vectors / scale[..., None])
        basis = np.zeros((*first.shape[:-1], 3, 3))  # (P, J, 3 params, 3 xyz)
        basis[..., 0, :] = first * scale[..., None]
        basis[..., 1, :] = second * scale[..., None]
        basis = np.where(constrained[..., None, None], basis, identity)
        flat = basis.reshape(n_people, n_params, 3)
        pull = tree.subtree @ (total[..., None] * (targets - positions))
        gradient = (basis * pull[:, :, None, :]).sum(axis=-1).reshape(n_people, n_params, 1)
        if keep is not None:
            flat, gradient = flat[:, keep], gradient[:, keep]
        normal = shared * (flat @ flat.transpose(0, 2, 1))
        normal[:, diagonal, diagonal] *= 1.0 + 1e-6
        normal[:, diagonal, diagonal] += padding
        solved = np.linalg.solve(normal, gradient)
        if keep is not None:
            step = np.zeros((n_people, n_params, 1))
            step[:, keep] = solved
            solved = step
        step = solved.reshape(n_people, n_joints, 3)
        candidate = vectors + (step[..., None] * basis).sum(axis=-2)
        norm = _norm(candidate)[..., None]
        candidate = np.where(constrained[..., None], candidate * scale[..., None] / norm, candidate)
        moved = tree.subtree_t @ candidate
        new_cost = _objective(moved, targets, total)
        better = (new_cost < cost) & np.isfinite(new_cost)
        vectors = np.where(better[:, None, None], candidate, vectors)
        positions = np.where(better[:, None, None], moved, positions)
        cost = np.where(better, new_cost, cost)
    return positions, vectors


class ReferenceMemory(Memory):
    """A ``Memory`` whose frame steps are numpy: ``learn`` and ``fit`` as the kernels compute."""

    def forget_stale(self, rows: np.ndarray, stamps: np.ndarray, timeout: float) -> None:
        """Forget the motion of rows unseen for over ``timeout`` s or stamped before it."""
        last = self.time_ns[rows]
        stale = self.timed[rows] & (((stamps - last) * 1e-9 > timeout) | (stamps < last))
        if stale.any():
            self.forget_motion(rows[stale])

    def remember(
        self, rows: np.ndarray, stamps: np.ndarray, seen: np.ndarray, vectors: np.ndarray
    ) -> None:
        """Take this frame's ``seen`` ``(P, J, 3)`` positions (NaN where absent) and vectors.

        A joint missing this frame keeps its last position (the prediction survives); the
        velocity is updated when the frames are at least 1 ms apart.
        """
        timed = self.timed[rows]
        previous = self.positions[rows]
        dt = np.where(timed, (stamps - self.time_ns[rows]) * 1e-9, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            velocities = (seen - previous) / np.where(dt > 0, dt, 1.0)[:, None, None]
        velocities = np.where(np.isfinite(velocities), velocities, 0.0)
        kept = np.where(np.isfinite(seen), seen, previous)
        self.positions[rows] = np.where(timed[:, None, None], kept, seen)
        update = (timed & (dt >= _MIN_VELOCITY_DT))[:, None, None]
        self.velocities[rows] = np.where(
            update, velocities, np.where(timed[:, None, None], self.velocities[rows], 0.0)
        )
        self.vectors[rows] = vectors
        self.time_ns[rows] = stamps
        self.timed[rows] = True

    def learn(
        self,
        rows: np.ndarray,
        stamps: np.ndarray,
        markers: np.ndarray,
        present: np.ndarray,
        *,
        settings: FitSettings,
    ) -> None:
        """``Memory.learn``: forget stale motion, push the lengths, remember the positions."""
        self.forget_stale(rows, stamps, settings.track_timeout)
        self.record(rows, markers, present)
        seen = np.where(present[..., None], markers[..., 1:4], np.nan)
        self.remember(rows, stamps, seen, np.full_like(seen, np.nan))

    def fit(
        self,
        rows: np.ndarray,
        stamps: np.ndarray,
        markers: np.ndarray,
        present: np.ndarray,
        lengths: np.ndarray,
        *,
        settings: FitSettings,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``Memory.fit``: prior from the motion, outlier weights, the fit, the new motion."""
        tree = self.tree
        self.forget_stale(rows, stamps, settings.track_timeout)
        dt = np.maximum(np.where(self.timed[rows], (stamps - self.time_ns[rows]) * 1e-9, 0.0), 0.0)
        prior = self.positions[rows] + self.velocities[rows] * dt[:, None, None]
        measured = markers[..., 1:4].copy()
        weights = _weights(markers, present, settings.confidence_floor)
        weights = weights * _outlier_factors(tree, measured, lengths, prior, settings)
        positions, vectors = fit_fixed_lengths(
            tree,
            measured,
            weights,
            lengths,
            prior=prior,
            prior_weight=settings.prior_weight,
            fallback_vectors=self.vectors[rows],
            sweeps=settings.sweeps,
            refinements=settings.refinements,
        )
        np.copyto(markers[..., 1:4], positions, where=present[..., None])
        self.remember(
            rows, stamps, np.where(present[..., None], markers[..., 1:4], np.nan), vectors
        )
        return link_rows(markers, present, self.layout)


def _outlier_factors(
    tree: KinematicTree,
    measured: np.ndarray,
    lengths: np.ndarray,
    prior: np.ndarray,
    settings: FitSettings,
) -> np.ndarray:
    """``(P, J)`` weight factors: < 1 for joints off both the body and the motion."""
    with np.errstate(invalid="ignore", divide="ignore"):
        error = np.abs(link_lengths(measured, tree.parents) - lengths) / lengths
        broken = error > settings.outlier_threshold  # (P, J) by child joint
        suspect = broken | ((broken.astype(float) @ tree.parent_of) > 0)
        distance = np.linalg.norm(measured - prior, axis=-1)
        factor = np.minimum(1.0, (settings.outlier_distance / distance) ** 2)
    return np.where(suspect & np.isfinite(factor), factor, 1.0)
