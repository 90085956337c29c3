"""Closest skeleton with fixed limb lengths: weighted least squares over a kinematic tree.

Each joint's position is written as the root position plus the link vectors on its path::

    x_j = r + sum_{c in path(root -> j)} v_c,        |v_c| = L_c for a calibrated link c

and the fit minimises ``sum_j w_j |x_j - m_j|^2`` over ``r`` and the ``v_c``. With every other
variable fixed, the best ``v_c`` has a closed form: the subtree below ``c`` moves rigidly with
``v_c``, so the objective in ``v_c`` is ``W_c |v_c|^2 - 2 v_c . g_c + const`` with ``W_c`` the
subtree weight and ``g_c = sum_{j in subtree(c)} w_j (m_j - x_j) + W_c v_c``. Under ``|v_c| = L_c``
the minimiser is ``L_c g_c / |g_c|`` (projection onto the sphere around the parent); a free
(uncalibrated) link takes ``g_c / W_c``; the root is a free "link" from the origin whose
subtree is the whole body. Links at the same tree depth have disjoint subtrees, so the
objective separates over them and one depth level is updated exactly in one vectorised step.
Sweeping root -> leaves is block-coordinate descent: it decreases the objective monotonically and
keeps every calibrated length exact after every step, but converges only linearly when a parent
and its children trade off. So one sweep (a good start) is followed by Gauss-Newton steps on the
tangent spaces of the length spheres (2 parameters per calibrated link, 3 per free one), whose
normal matrix has the closed form ``H[(c,a),(d,b)] = W[c,d] (B_ca . B_db)`` with ``W[c,d]`` the
weight of the joints below both ``c`` and ``d``; the step is retracted onto the spheres by
normalising and kept only where it lowers the objective.

Shapes: ``P`` people, ``J`` joints, positions ``(P, J, 3)`` in metres, weights ``(P, J)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hiros_core.layouts import Layout

__all__ = ["KinematicTree", "fit_fixed_lengths", "link_lengths"]

_EPS = 1e-12


@dataclass(frozen=True)
class KinematicTree:
    """Index tables of a layout's joint tree, computed once per layout.

    Attributes:
        parents: ``(J,)`` parent of each joint, ``-1`` for roots.
        levels: joint indices grouped by depth; ``levels[0]`` holds the roots.
        subtree: ``(J, J)`` float, ``subtree[c, j] = 1`` when ``j`` is ``c`` or below it.
        level_subtrees: ``subtree`` rows of each level (who is below each of its joints).
        level_below: the transposes of ``level_subtrees``, contiguous (moves subtrees).
        subtree_t: ``subtree.T``, contiguous (link vectors -> positions by one product).
        has_parent: ``(J,)`` True for joints that end a link.
        parent_of: ``(J, J)`` float, ``parent_of[c, p] = 1`` when ``p`` is ``c``'s parent, so
            ``flags @ parent_of`` moves per-link flags (by child) to the parents.
        order: ``(J,)`` the joints level by level (parents before children).
        level_starts: ``(levels + 1,)`` where each level begins in ``order``.

    """

    parents: np.ndarray
    levels: tuple[np.ndarray, ...]
    subtree: np.ndarray
    level_subtrees: tuple[np.ndarray, ...]
    level_below: tuple[np.ndarray, ...]
    subtree_t: np.ndarray
    has_parent: np.ndarray
    parent_of: np.ndarray
    order: np.ndarray
    level_starts: np.ndarray

    @classmethod
    def from_layout(cls, layout: Layout) -> KinematicTree:
        """Build the tables; the layout guarantees a valid forest (checked in ``Layout``)."""
        parents = np.asarray(layout.parents, dtype=np.int64)
        n = len(parents)
        depth = np.full(n, -1)
        # Depth by repeated relaxation: at most tree-height passes, done once per layout.
        depth[parents < 0] = 0
        while (depth < 0).any():
            ready = (depth < 0) & (depth[parents] >= 0) & (parents >= 0)
            depth[ready] = depth[parents[ready]] + 1
        subtree = np.eye(n)
        for joint in range(n):
            ancestor = parents[joint]
            while ancestor >= 0:
                subtree[ancestor, joint] = 1.0
                ancestor = parents[ancestor]
        levels = tuple(np.flatnonzero(depth == d) for d in range(depth.max() + 1))
        parent_of = np.zeros((n, n))
        children = np.flatnonzero(parents >= 0)
        parent_of[children, parents[children]] = 1.0
        return cls(
            parents=parents,
            levels=levels,
            subtree=subtree,
            level_subtrees=tuple(subtree[level] for level in levels),
            level_below=tuple(np.ascontiguousarray(subtree[level].T) for level in levels),
            subtree_t=np.ascontiguousarray(subtree.T),
            has_parent=parents >= 0,
            parent_of=parent_of,
            order=np.concatenate(levels).astype(np.int64),
            level_starts=np.cumsum([0, *map(len, levels)]).astype(np.int64),
        )


def _norm(vectors: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(vectors, axis=-1)``: the same arithmetic without its wrapper."""
    return np.sqrt(np.add.reduce(vectors * vectors, axis=-1))


def link_lengths(positions: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """``(..., J)`` distance of each joint from its parent; NaN for roots and missing ends."""
    parent_positions = positions[..., np.maximum(parents, 0), :]
    lengths = np.linalg.norm(positions - parent_positions, axis=-1)
    lengths[..., parents < 0] = np.nan
    return lengths


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
    compiled: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Joint positions closest to ``measured`` (weighted) whose calibrated links keep ``lengths``.

    Args:
        tree: the layout's tables.
        measured: ``(P, J, 3)`` measured positions (NaN where unknown, with weight 0 there).
        weights: ``(P, J)`` non-negative measurement weights (confidences, down-weighted outliers).
        lengths: ``(P, J)`` length of the link ending at each joint; NaN = free link (roots,
            uncalibrated links), which then follows the measurement without a constraint.
        prior: ``(P, J, 3)`` predicted positions (NaN where none). A small prior keeps joints
            without a usable measurement where motion predicts them instead of undefined.
        prior_weight: weight of the prior relative to a confidence of 1.
        fallback_vectors: ``(P, J, 3)`` link vectors to start from where the measurement cannot
            give a direction (usually last frame's solution).
        sweeps: root-to-leaves sweeps of block-coordinate descent (the start).
        refinements: Gauss-Newton steps after the sweeps.
        compiled: run the numba kernel of :mod:`hiros_optimizer.compiled` (the same algorithm
            and results up to rounding, ~50x faster; compiled on first use) instead of numpy.

    Returns:
        ``(P, J, 3)`` positions and ``(P, J, 3)`` link vectors (child minus parent; the root's
        row is its position). Calibrated links have exactly their length.

    """
    if compiled:
        from hiros_optimizer.compiled import fit_people

        return fit_people(
            tree.parents, tree.order, tree.level_starts, measured, weights, lengths,
            prior=prior, prior_weight=prior_weight, fallback_vectors=fallback_vectors,
            sweeps=sweeps, refinements=refinements,
        )  # fmt: skip
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
