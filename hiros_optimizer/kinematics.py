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

import numpy as np

from hiros_core.kinematics import KinematicTree

__all__ = ["fit_fixed_lengths"]


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
    """Joint positions closest to ``measured`` (weighted) whose calibrated links keep ``lengths``.

    The compiled kernel (``hiros_optimizer.compiled``) of the module docstring's fit; its
    numpy statement is ``test/support/optimizer_reference.py``'s, which a test holds it to.

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

    Returns:
        ``(P, J, 3)`` positions and ``(P, J, 3)`` link vectors (child minus parent; the root's
        row is its position). Calibrated links have exactly their length.

    """
    from hiros_optimizer.compiled import fit_people

    return fit_people(
        tree.parents,
        tree.order,
        tree.level_starts,
        measured,
        weights,
        lengths,
        prior=prior,
        prior_weight=prior_weight,
        fallback_vectors=fallback_vectors,
        sweeps=sweeps,
        refinements=refinements,
    )
