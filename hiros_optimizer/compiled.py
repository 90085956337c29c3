"""The fixed-length fit of :mod:`hiros_optimizer.kinematics`, compiled with numba.

The same algorithm, step for step (start, block-coordinate sweeps, Gauss-Newton with the same
damping, retraction and acceptance test), written as loops over people and joints. Its numpy
statement (``test/support/optimizer_reference.py``, which a test holds these kernels to)
spends nearly all its time in the overhead of ~150 small array calls per frame; these loops
do the arithmetic only. Two parts are computed differently, with the same results up to
rounding:

- sums over subtrees are accumulated leaves -> root in one pass (instead of products with the
  ``(J, J)`` subtree matrix), and positions are rebuilt root -> leaves;
- the Gauss-Newton system is not formed: the linearised problem is a quadratic over a tree,
  minimised exactly by eliminating the joints leaves -> root. Write ``d_j`` for the change of
  joint ``j``'s position; ``d_c = d_p + B_c θ_c`` along a link (``B_c`` its tangent basis, the
  identity for a free link or the root). The cost of a subtree as a function of its top joint's
  change is a quadratic ``dᵀ A d - 2 bᵀ d``, with ``A_c = w_c I + Σ A'_k`` and
  ``b_c = w_c e_c + Σ b'_k`` over its children (``e`` = target - position). Minimising a
  child's ``θ`` (with the same ridge ``λ |θ|²`` as the dense solve's damping) leaves
  ``A' = A - A G A``, ``b' = b - A G b`` with ``G = B (BᵀAB + λI)⁻¹ Bᵀ`` for the parent. The
  root's step solves ``(A + λI) θ = b``; each child then takes
  ``θ = (BᵀAB + λI)⁻¹ Bᵀ (b - A d_p)``. That is the dense normal equations' solution, in
  O(J) 3×3 operations instead of an O(J³) factorisation.

Nothing here is compiled at import: numba compiles on the first call (cached on disk with
``cache=True``), and only the optimizer imports this module.
"""

# Numba kernels: untyped array arguments passed positionally, long straight-line loops.
# ruff: noqa: ANN001, ANN201, ANN202, PLR0912, PLR0915, PLR0917

from __future__ import annotations

import numpy as np
from numba import njit

from hiros_core.compiled import _link_rows, refresh_stale_caches
from hiros_optimizer.kernel_args import FitTree

__all__ = ["fit_frame", "fit_frame_links", "fit_people", "learn_frame"]

_EPS = 1e-12
_MIN_VELOCITY_DT = 1e-3  # s; closer frames (duplicates) would turn noise into huge velocities


@njit(cache=True, error_model="numpy")
def _forward(parents, order, vectors, positions, first=0):
    """Positions from link vectors, root outwards, of the joints from ``order[first]`` on.

    A sweep moves only the links of one depth and below, so the joints above keep their
    positions (recomputing them would give the same numbers).
    """
    for index in range(first, len(order)):
        j = order[index]
        p = parents[j]
        for k in range(3):
            positions[j, k] = vectors[j, k] if p < 0 else positions[p, k] + vectors[j, k]


@njit(cache=True, error_model="numpy")
def _subtree_weights(parents, order, values, out):
    """``out[c] = Σ values[j]`` over ``j`` at and below ``c``, for ``(J,)`` values."""
    out[:] = values
    for index in range(len(order) - 1, -1, -1):
        j = order[index]
        p = parents[j]
        if p >= 0:
            out[p] += out[j]


@njit(cache=True, error_model="numpy")
def _subtree_sums(parents, order, values, out, first=0, stop=0):
    """``out[c] = Σ values[j]`` over ``j`` at and below ``c``, for ``(J, 3)`` rows.

    Only the joints from ``order[first]`` on are summed, and only the joints from
    ``order[stop]`` on passed to their parents (``stop`` > ``first`` where the parents above
    ``order[first]`` are not wanted); the additions are those of the full sum, in its order.
    Element by element: a row expression (``out[p] += out[j]``) allocates a temporary.
    """
    for index in range(first, len(order)):
        j = order[index]
        for k in range(3):
            out[j, k] = values[j, k]
    for index in range(len(order) - 1, max(first, stop) - 1, -1):
        j = order[index]
        p = parents[j]
        if p >= 0:
            for k in range(3):
                out[p, k] += out[j, k]


@njit(cache=True, error_model="numpy")
def _cost(positions, targets, total):
    cost = 0.0
    for j in range(len(total)):
        for k in range(3):
            delta = positions[j, k] - targets[j, k]
            cost += total[j] * delta * delta
    return cost


@njit(cache=True, error_model="numpy")
def _inverse3(m, out):
    """Inverse of a symmetric positive definite 3×3 matrix by cofactors."""
    c00 = m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]
    c01 = m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2]
    c02 = m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]
    det = m[0, 0] * c00 + m[0, 1] * c01 + m[0, 2] * c02
    inv = 1.0 / det
    out[0, 0] = c00 * inv
    out[1, 0] = c01 * inv
    out[2, 0] = c02 * inv
    out[0, 1] = (m[0, 2] * m[2, 1] - m[0, 1] * m[2, 2]) * inv
    out[1, 1] = (m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]) * inv
    out[2, 1] = (m[0, 1] * m[2, 0] - m[0, 0] * m[2, 1]) * inv
    out[0, 2] = (m[0, 1] * m[1, 2] - m[0, 2] * m[1, 1]) * inv
    out[1, 2] = (m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2]) * inv
    out[2, 2] = (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]) * inv


@njit(cache=True, error_model="numpy")
def _initial(parents, order, targets, total, lengths, fallback, vectors, positions):
    """``kinematics._initial_vectors`` of one person."""
    n = len(parents)
    below = np.empty(n)
    _subtree_weights(parents, order, total, below)
    weighted = np.empty((n, 3))
    for j in range(n):
        for k in range(3):
            weighted[j, k] = total[j] * targets[j, k]
    centroid = np.empty((n, 3))
    _subtree_sums(parents, order, weighted, centroid)
    vector = np.empty(3)
    for j in order:
        p = parents[j]
        has_aim = below[j] > 0
        for k in range(3):
            if total[j] > 0:
                aim = targets[j, k]
            elif has_aim:
                aim = centroid[j, k] / below[j]
            else:
                aim = targets[j, k]
            vector[k] = aim - (positions[p, k] if p >= 0 else 0.0)
        if not has_aim:
            if (
                np.isfinite(fallback[j, 0])
                and np.isfinite(fallback[j, 1])
                and np.isfinite(fallback[j, 2])
            ):
                vector[:] = fallback[j]
            elif p >= 0:
                vector[0], vector[1], vector[2] = 0.0, 0.0, -1.0
            else:
                vector[:] = 0.0
        constrained = np.isfinite(lengths[j])
        norm = np.sqrt(vector[0] ** 2 + vector[1] ** 2 + vector[2] ** 2)
        if constrained:
            if norm < _EPS:
                vector[0], vector[1], vector[2] = 0.0, 0.0, -1.0
                norm = 1.0
            for k in range(3):
                vector[k] *= lengths[j] / norm
        for k in range(3):
            vectors[j, k] = vector[k]
            positions[j, k] = vector[k] + (positions[p, k] if p >= 0 else 0.0)


@njit(cache=True, error_model="numpy")
def _sweeps(parents, order, level_starts, targets, total, lengths, vectors, positions, sweeps):
    """``kinematics._coordinate_sweeps`` of one person."""
    n = len(parents)
    below = np.empty(n)
    _subtree_weights(parents, order, total, below)
    residual = np.empty((n, 3))
    pull = np.empty((n, 3))
    for _ in range(sweeps):
        for level in range(len(level_starts) - 1):
            # Only this depth's links move: the sums below them and the positions from them.
            first, stop = level_starts[level], level_starts[level + 1]
            for index in range(first, n):
                j = order[index]
                for k in range(3):
                    residual[j, k] = total[j] * (targets[j, k] - positions[j, k])
            _subtree_sums(parents, order, residual, pull, first, stop)
            for index in range(first, stop):
                c = order[index]
                w = below[c]
                for k in range(3):
                    pull[c, k] += w * vectors[c, k]
                norm = np.sqrt(pull[c, 0] ** 2 + pull[c, 1] ** 2 + pull[c, 2] ** 2)
                if w > _EPS and norm > _EPS:
                    for k in range(3):
                        if np.isfinite(lengths[c]):
                            vectors[c, k] = lengths[c] * pull[c, k] / norm
                        else:
                            vectors[c, k] = pull[c, k] / w
            _forward(parents, order, vectors, positions, first)


@njit(cache=True, error_model="numpy")
def _basis(vector, length, out):
    """Tangent basis rows (scaled by the length) of a calibrated link; third row zero."""
    d0, d1, d2 = vector[0] / length, vector[1] / length, vector[2] / length
    if abs(d0) < 0.9:
        h0, h1, h2 = 1.0, 0.0, 0.0
    else:
        h0, h1, h2 = 0.0, 1.0, 0.0
    f0 = d1 * h2 - d2 * h1
    f1 = d2 * h0 - d0 * h2
    f2 = d0 * h1 - d1 * h0
    norm = np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
    f0, f1, f2 = f0 / norm, f1 / norm, f2 / norm
    out[0, 0], out[0, 1], out[0, 2] = f0 * length, f1 * length, f2 * length
    out[1, 0] = (d1 * f2 - d2 * f1) * length
    out[1, 1] = (d2 * f0 - d0 * f2) * length
    out[1, 2] = (d0 * f1 - d1 * f0) * length
    out[2, :] = 0.0


@njit(cache=True, error_model="numpy")
def _gauss_newton(parents, order, targets, total, lengths, vectors, positions, refinements):
    """``kinematics._gauss_newton`` of one person, by elimination over the tree."""
    n = len(parents)
    below = np.empty(n)
    _subtree_weights(parents, order, total, below)
    basis = np.zeros((n, 3, 3))  # rows: the link's parameter directions
    quad = np.empty((n, 3, 3))  # A of each joint's subtree
    linear = np.empty((n, 3))  # b of each joint's subtree
    solve = np.empty((n, 3, 3))  # (BᵀAB + λI)⁻¹ Bᵀ of each link
    ab = np.empty((3, 3))
    m = np.empty((3, 3))
    m_inv = np.empty((3, 3))
    g = np.empty((3, 3))
    ag = np.empty((3, 3))
    rhs = np.empty(3)
    theta = np.empty(3)
    change = np.empty((n, 3))
    candidate = np.empty((n, 3))
    moved = np.empty((n, 3))
    cost = _cost(positions, targets, total)
    for _ in range(refinements):
        for j in range(n):
            if np.isfinite(lengths[j]):
                _basis(vectors[j], lengths[j], basis[j])
            else:
                basis[j, :, :] = 0.0
                for k in range(3):
                    basis[j, k, k] = 1.0
            for a in range(3):
                linear[j, a] = total[j] * (targets[j, a] - positions[j, a])
                for b in range(3):
                    quad[j, a, b] = total[j] if a == b else 0.0
        # Leaves -> root: each link's child subtree folded into its parent's quadratic.
        for index in range(n - 1, -1, -1):
            c = order[index]
            constrained = np.isfinite(lengths[c])
            ridge = 1e-6 * below[c] * (lengths[c] ** 2 if constrained else 1.0) + 1e-9
            B = basis[c]
            A = quad[c]
            for a in range(3):  # ab = A Bᵀ (3 × params)
                for b in range(3):
                    ab[a, b] = A[a, 0] * B[b, 0] + A[a, 1] * B[b, 1] + A[a, 2] * B[b, 2]
            for a in range(3):  # m = B A Bᵀ + λ I; padded parameter: unit diagonal
                for b in range(3):
                    m[a, b] = B[a, 0] * ab[0, b] + B[a, 1] * ab[1, b] + B[a, 2] * ab[2, b]
                m[a, a] += ridge
            if constrained:
                m[2, 2] = 1.0 + ridge
            _inverse3(m, m_inv)
            for a in range(3):  # solve = m⁻¹ B
                for b in range(3):
                    solve[c, a, b] = (
                        m_inv[a, 0] * B[0, b] + m_inv[a, 1] * B[1, b] + m_inv[a, 2] * B[2, b]
                    )
            p = parents[c]
            if p < 0:
                continue
            for a in range(3):  # g = Bᵀ m⁻¹ B
                for b in range(3):
                    g[a, b] = (
                        B[0, a] * solve[c, 0, b]
                        + B[1, a] * solve[c, 1, b]
                        + (B[2, a] * solve[c, 2, b])
                    )
            for a in range(3):  # ag = A g
                for b in range(3):
                    ag[a, b] = A[a, 0] * g[0, b] + A[a, 1] * g[1, b] + A[a, 2] * g[2, b]
            for a in range(3):
                linear[p, a] += linear[c, a] - (
                    ag[a, 0] * linear[c, 0] + ag[a, 1] * linear[c, 1] + ag[a, 2] * linear[c, 2]
                )
                for b in range(3):
                    quad[p, a, b] += A[a, b] - (
                        ag[a, 0] * A[0, b] + ag[a, 1] * A[1, b] + ag[a, 2] * A[2, b]
                    )
        # Root -> leaves: each link's step given its parent's change.
        for j in order:
            p = parents[j]
            for a in range(3):
                rhs[a] = linear[j, a]
                if p >= 0:
                    rhs[a] -= (
                        quad[j, a, 0] * change[p, 0]
                        + quad[j, a, 1] * change[p, 1]
                        + quad[j, a, 2] * change[p, 2]
                    )
            for a in range(3):
                theta[a] = (
                    solve[j, a, 0] * rhs[0] + solve[j, a, 1] * rhs[1] + (solve[j, a, 2] * rhs[2])
                )
            for k in range(3):
                step = (
                    theta[0] * basis[j, 0, k]
                    + theta[1] * basis[j, 1, k]
                    + (theta[2] * basis[j, 2, k])
                )
                change[j, k] = step + (change[p, k] if p >= 0 else 0.0)
                candidate[j, k] = vectors[j, k] + step
            if np.isfinite(lengths[j]):
                norm = np.sqrt(candidate[j, 0] ** 2 + candidate[j, 1] ** 2 + candidate[j, 2] ** 2)
                for k in range(3):
                    candidate[j, k] *= lengths[j] / norm
        _forward(parents, order, candidate, moved)
        new_cost = _cost(moved, targets, total)
        if new_cost < cost and np.isfinite(new_cost):
            vectors[:] = candidate
            positions[:] = moved
            cost = new_cost


@njit(cache=True, error_model="numpy")
def _fit_person(tree, fit, measured, weights, lengths, prior, fallback, vectors, positions):
    """The fit of one person: ``(J, 3)`` measured, prior, fallback; ``(J,)`` weights, lengths.

    Each joint's target is the weighted mean of its measurement (weight ``w``, 0 when not
    finite) and its prior (weight ``prior_weight`` where finite); the link vectors of fixed
    ``lengths`` then minimise ``Σ_j total_j |x_j - target_j|²`` (``x`` the forward kinematics):
    an initial guess, ``sweeps`` of coordinate descent, ``refinements`` Gauss-Newton steps.
    ``tree`` is ``(parents, order, level_starts)``, ``fit`` ``(prior_weight, sweeps,
    refinements)``. Writes the link vectors and positions into ``vectors`` and ``positions``.
    """
    parents, order, level_starts = tree
    prior_weight, sweeps, refinements = fit
    n = len(parents)
    targets = np.zeros((n, 3))
    total = np.zeros(n)
    for j in range(n):
        m = measured[j]
        w = weights[j]
        finite = np.isfinite(m[0]) and np.isfinite(m[1]) and np.isfinite(m[2])
        if not finite or not np.isfinite(w) or w < 0:
            w = 0.0
        q = prior[j]
        has_prior = (
            prior_weight > 0 and np.isfinite(q[0]) and np.isfinite(q[1]) and np.isfinite(q[2])
        )
        total[j] = w + (prior_weight if has_prior else 0.0)
        for k in range(3):
            value = w * m[k] if w > 0 else 0.0
            if has_prior:
                value += prior_weight * q[k]
            targets[j, k] = value / total[j] if total[j] > 0 else 0.0
    _initial(parents, order, targets, total, lengths, fallback, vectors, positions)
    _sweeps(parents, order, level_starts, targets, total, lengths, vectors, positions, sweeps)
    _gauss_newton(parents, order, targets, total, lengths, vectors, positions, refinements)


@njit(cache=True, error_model="numpy")
def _fit(tree, fit, measured, weights, lengths, prior, fallback):
    """:func:`_fit_person` for each person of ``(P, J, ...)`` arrays; ``(positions, vectors)``."""
    n_people, n = weights.shape
    positions = np.zeros((n_people, n, 3))
    vectors = np.zeros((n_people, n, 3))
    for person in range(n_people):
        _fit_person(
            tree,
            fit,
            measured[person],
            weights[person],
            lengths[person],
            prior[person],
            fallback[person],
            vectors[person],
            positions[person],
        )
    return positions, vectors


# --------------------------------------------------------------- one frame of the stage
# ``hiros_optimizer.memory.Memory``'s numpy steps for all people of a frame in one call: the
# same formulas in the same order (norms summed x, y, z as numpy does), so the same numbers.
# Memory arrays: ``positions``, ``velocities``, ``vectors`` ``(S, J, 3)``, ``time_ns`` ``(S,)``,
# ``timed`` ``(S,)`` (False: no motion known; then positions and vectors are NaN, velocities 0).


@njit(cache=True, error_model="numpy")
def _forget_stale(s, stamp, time_ns, timed, positions, velocities, vectors, timeout):
    """``Memory.forget_stale`` of memory row ``s``."""
    if timed[s] and ((stamp - time_ns[s]) * 1e-9 > timeout or stamp < time_ns[s]):
        timed[s] = False
        positions[s] = np.nan
        velocities[s] = 0.0
        vectors[s] = np.nan


@njit(cache=True, error_model="numpy")
def _remember(s, stamp, seen, fitted, time_ns, timed, positions, velocities, vectors):
    """``Memory.remember`` of memory row ``s``: ``seen`` ``(J, 3)`` NaN where absent."""
    was_timed = timed[s]
    dt = (stamp - time_ns[s]) * 1e-9 if was_timed else 0.0
    divisor = dt if dt > 0 else 1.0
    for j in range(seen.shape[0]):
        for k in range(3):
            value = seen[j, k]
            if was_timed:
                previous = positions[s, j, k]
                velocity = (value - previous) / divisor
                if dt >= _MIN_VELOCITY_DT:
                    velocities[s, j, k] = velocity if np.isfinite(velocity) else 0.0
                positions[s, j, k] = value if np.isfinite(value) else previous
            else:
                velocities[s, j, k] = 0.0
                positions[s, j, k] = value
            vectors[s, j, k] = fitted[j, k]
    time_ns[s] = stamp
    timed[s] = True


@njit(cache=True, error_model="numpy")
def _norm3(a, b):
    """``np.linalg.norm(a - b)`` of two 3-vectors (x² + y², then + z², as numpy sums)."""
    d0, d1, d2 = a[0] - b[0], a[1] - b[1], a[2] - b[2]
    return np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@njit(cache=True, error_model="numpy")
def _weight(confidence, present, floor):
    """``_stacked_weights`` of one joint: NaN confidence counts 1, at least ``floor``."""
    if not present:
        return 0.0
    c = confidence if np.isfinite(confidence) else 1.0
    return c if c >= floor else floor


@njit(cache=True, error_model="numpy")
def fit_frame(tree, frame, lengths, memory, settings):
    """``Memory.fit``: prior, outlier weights, fit, output positions, memory, in place.

    For each person: the prior of joint ``j`` is ``position + velocity · dt`` of its memory row;
    a link whose relative length error ``|‖m_j - m_parent‖ - l_j| / l_j`` exceeds ``threshold``
    makes both its ends suspect; a joint's weight is its confidence (NaN: 1, at least
    ``floor``), times ``min(1, (distance / ‖m_j - prior_j‖)²)`` when suspect; then
    :func:`_fit_person`, and the fitted positions go into the present joints' rows and the
    memory.

    Args:
        tree: ``kernel_args.FitTree``.
        frame: ``kernel_args.FrameRows``; ``markers`` ``(P, J, 20)`` are the output rows
            (fitted positions written where present).
        lengths: ``(P, J)`` the people's calibrations.
        memory: ``kernel_args.MemoryState`` (updated in place).
        settings: ``kernel_args.FitSettings``.

    """
    parents = tree[0]
    markers, present, rows, stamps = frame
    time_ns, timed, positions, velocities, vectors = memory
    floor, threshold, distance, prior_weight, timeout, sweeps, refinements = settings
    fit = (prior_weight, sweeps, refinements)
    n_people, n = present.shape
    measured = np.empty((n, 3))
    prior = np.empty((n, 3))
    weights = np.empty(n)
    broken = np.empty(n, dtype=np.bool_)
    suspect = np.empty(n, dtype=np.bool_)
    fitted = np.empty((n, 3))
    moved = np.empty((n, 3))
    for i in range(n_people):
        s = rows[i]
        _forget_stale(s, stamps[i], time_ns, timed, positions, velocities, vectors, timeout)
        dt = (stamps[i] - time_ns[s]) * 1e-9 if timed[s] else 0.0
        dt = max(dt, 0.0)
        for j in range(n):
            for k in range(3):
                measured[j, k] = markers[i, j, 1 + k]
                prior[j, k] = positions[s, j, k] + velocities[s, j, k] * dt
            suspect[j] = False
        # Outliers: ends of a link off its length, when also far from the motion.
        for j in range(n):
            p = parents[j]
            error = np.nan
            if p >= 0:
                error = abs(_norm3(measured[j], measured[p]) - lengths[i, j]) / lengths[i, j]
            broken[j] = error > threshold
            if broken[j]:
                suspect[j] = True
                suspect[p] = True
        for j in range(n):
            weight = _weight(markers[i, j, 0], present[i, j], floor)
            if suspect[j]:
                ratio = distance / _norm3(measured[j], prior[j])
                factor = min(1.0, ratio * ratio) if np.isfinite(ratio) else np.nan
                if np.isfinite(factor):
                    weight *= factor
            weights[j] = weight
        _fit_person(tree, fit, measured, weights, lengths[i], prior, vectors[s], fitted, moved)
        for j in range(n):
            for k in range(3):
                if present[i, j]:
                    markers[i, j, 1 + k] = moved[j, k]
                measured[j, k] = moved[j, k] if present[i, j] else np.nan
        _remember(s, stamps[i], measured, fitted, time_ns, timed, positions, velocities, vectors)


@njit(cache=True, error_model="numpy")
def fit_frame_links(tree, frame, lengths, memory, settings, link_ends):
    """:func:`fit_frame`, then the fitted rows' links (``model.link_rows``): one call a frame.

    ``link_ends`` is ``(parents, children)`` of the layout's links.
    """
    fit_frame(tree, frame, lengths, memory, settings)
    return _link_rows(frame[0], frame[1], link_ends[0], link_ends[1])


@njit(cache=True, error_model="numpy")
def learn_frame(parents, frame, memory, window, filled, timeout):
    """``Memory.learn``: push each person's link lengths into their window, remember them.

    Each person's link lengths ``‖m_j - m_parent‖`` over the joints of confidence above 0 (NaN
    counts as 1) go into column ``filled % N`` of their ``window`` ``(S, J, N)`` row
    (``filled`` ``(S,)`` counts up); the present joints become the memory row's positions.
    ``frame`` is a ``kernel_args.FrameRows``, ``memory`` a ``kernel_args.MemoryState``
    (updated in place), ``timeout`` in seconds.
    """
    markers, present, rows, stamps = frame
    time_ns, timed, positions, velocities, vectors = memory
    n_people, n = present.shape
    size = window.shape[2]
    counted = np.empty((n, 3))
    seen = np.empty((n, 3))
    no_vectors = np.full((n, 3), np.nan)
    for i in range(n_people):
        s = rows[i]
        _forget_stale(s, stamps[i], time_ns, timed, positions, velocities, vectors, timeout)
        for j in range(n):
            keep = _weight(markers[i, j, 0], present[i, j], 0.0) > 0
            for k in range(3):
                counted[j, k] = markers[i, j, 1 + k] if keep else np.nan
                seen[j, k] = markers[i, j, 1 + k] if present[i, j] else np.nan
        column = filled[s] % size
        for j in range(n):
            p = parents[j]
            window[s, j, column] = _norm3(counted[j], counted[p]) if p >= 0 else np.nan
        filled[s] += 1
        _remember(s, stamps[i], seen, no_vectors, time_ns, timed, positions, velocities, vectors)


def fit_people(
    parents: np.ndarray,
    order: np.ndarray,
    level_starts: np.ndarray,
    measured: np.ndarray,
    weights: np.ndarray,
    lengths: np.ndarray,
    *,
    prior: np.ndarray | None,
    prior_weight: float,
    fallback_vectors: np.ndarray | None,
    sweeps: int,
    refinements: int,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`hiros_optimizer.kinematics.fit_fixed_lengths` through the compiled kernel."""
    shape = measured.shape
    prior = np.full(shape, np.nan) if prior is None else np.ascontiguousarray(prior, float)
    fallback = (
        np.full(shape, np.nan)
        if fallback_vectors is None
        else np.ascontiguousarray(fallback_vectors, float)
    )
    return _fit(
        FitTree(parents, order, level_starts),
        (float(prior_weight), int(sweeps), int(refinements)),
        np.ascontiguousarray(measured, float),
        np.ascontiguousarray(weights, float),
        np.ascontiguousarray(lengths, float),
        prior,
        fallback,
    )


refresh_stale_caches(globals())  # the kernels above call hiros_core.compiled's _link_rows
