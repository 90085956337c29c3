"""The filter's per-frame arithmetic as numba kernels (same results as the numpy versions).

:class:`hiros_filter.estimators.KalmanBank` (predict, then masked correction),
:class:`hiros_filter.lengths.LengthKeeper` (input lengths, held links, projection) and the
slerp smoothing of orientations with their angular rates, written as loops over the frame's
tracks and joints. The numpy versions are kept as the readable reference (tests compare the
two); at a few people the numpy calls' overhead, not the arithmetic, was the filter's cost.
Subtree sums of the projection are one root -> leaves pass (each joint moves by the
corrections of the links above it) instead of a product with the ``(J, J)`` subtree matrix.

:func:`filter_step` is a whole Kalman-mode frame in one call (the three kernels above plus the
joint bookkeeping and ``hiros_core.model.link_rows``): at ~3 people per frame, each kernel call
and the numpy glue between them cost more than the arithmetic.

Compiled on first use (cached on disk with ``cache=True``), never at import of the package.
"""

# Numba kernels: untyped array arguments passed positionally, long straight-line loops.
# ruff: noqa: ANN001, ANN201, PLR0912, PLR0915, PLR0917

from __future__ import annotations

import numpy as np
from numba import njit

from hiros_core.compiled import _link_rows, refresh_stale_caches
from hiros_filter.kernel_args import KalmanFrame

__all__ = ["filter_step", "kalman_step", "keep_lengths", "smooth_orientations"]

_EPS = 1e-12
_SAME_LENGTH = 1e-9


@njit(cache=True)
def kalman_step(state, model, frame):
    """``KalmanBank.predict(rows, dt)`` then ``KalmanBank.correct(rows, mask, positions)``.

    For each row's slot and joint: ``x ← F x``, ``P ← F P Fᵀ + scale · Q(dt_rounded)`` with
    ``F = [[1, dt, dt²/2], [0, 1, dt], [0, 0, 1]]`` and ``Q`` the continuous white-jerk noise of
    density ``q``; then where ``mask``, with ``H = [1, 0, 0]``: gain ``K = P[:, 0] / (P[0, 0] +
    r)``, ``x += K ν`` for the innovation ``ν = position - x[0]``, ``P -= K P[0, :]``, and (when
    ``max_scale > 1``) ``scale`` smoothed at ``rate`` towards ``|ν|² / (3 (P[0, 0] + r))``
    within ``[1, max_scale]``.

    Args:
        state: ``kernel_args.KalmanState`` ``(x, P, scale)``, updated in place.
        model: ``kernel_args.KalmanModel`` ``(q, r, max_scale, rate, initial)``.
        frame: ``kernel_args.KalmanFrame`` ``(rows, dt, dt_rounded, mask, positions)``.

    """
    x, P, scale = state
    q, r, max_scale, rate, _ = model
    rows, dt, dt_rounded, mask, positions = frame
    n_joints = x.shape[3]
    q_matrix = np.empty((3, 3))
    for i in range(len(rows)):
        s = rows[i]
        h = dt[i]
        half = 0.5 * h * h
        t = dt_rounded[i]
        q_matrix[0, 0] = t**5 / 20.0 * q
        q_matrix[0, 1] = q_matrix[1, 0] = t**4 / 8.0 * q
        q_matrix[0, 2] = q_matrix[2, 0] = t**3 / 6.0 * q
        q_matrix[1, 1] = t**3 / 3.0 * q
        q_matrix[1, 2] = q_matrix[2, 1] = t**2 / 2.0 * q
        q_matrix[2, 2] = t * q
        for j in range(n_joints):
            for axis in range(3):
                x[s, 0, axis, j] += h * x[s, 1, axis, j] + half * x[s, 2, axis, j]
                x[s, 1, axis, j] += h * x[s, 2, axis, j]
            for b in range(3):  # F P, row by row
                P[s, 0, b, j] += h * P[s, 1, b, j] + half * P[s, 2, b, j]
                P[s, 1, b, j] += h * P[s, 2, b, j]
            for a in range(3):  # (F P) Fᵀ, column by column
                P[s, a, 0, j] += h * P[s, a, 1, j] + half * P[s, a, 2, j]
                P[s, a, 1, j] += h * P[s, a, 2, j]
            noise = scale[s, j]
            for a in range(3):
                for b in range(3):
                    P[s, a, b, j] += q_matrix[a, b] * noise
            if not mask[i, j]:
                continue
            variance = P[s, 0, 0, j] + r
            g0 = P[s, 0, 0, j] / variance
            g1 = P[s, 1, 0, j] / variance
            g2 = P[s, 2, 0, j] / variance
            surprise = 0.0
            for axis in range(3):
                innovation = positions[i, j, axis] - x[s, 0, axis, j]
                surprise += innovation * innovation
                x[s, 0, axis, j] += g0 * innovation
                x[s, 1, axis, j] += g1 * innovation
                x[s, 2, axis, j] += g2 * innovation
            if max_scale > 1.0:
                smoothed = noise + rate * (surprise / (3.0 * variance) - noise)
                scale[s, j] = min(max(smoothed, 1.0), max_scale)
            p00, p01, p02 = P[s, 0, 0, j], P[s, 0, 1, j], P[s, 0, 2, j]
            for a, g in ((0, g0), (1, g1), (2, g2)):
                P[s, a, 0, j] -= g * p00
                P[s, a, 1, j] -= g * p01
                P[s, a, 2, j] -= g * p02


@njit(cache=True)
def keep_lengths(parents, order, states, measured, present, previous_lengths):
    """Input lengths, held links and ``LengthKeeper.project`` for a frame's tracks at once.

    Args:
        parents: ``(J,)`` the layout's tree (``KinematicTree.parents``).
        order: ``(J,)`` parents before children (``KinematicTree.order``).
        states: ``(3, n, J, 3)`` positions, velocities, accelerations; projected in place.
        measured: ``(n, J, 3)`` input positions.
        present: ``(n, J)`` joints in the input (their mean position is kept).
        previous_lengths: ``(n, J)`` the tracks' input lengths of the previous frame.

    Returns:
        ``(n, J)`` this frame's input lengths (NaN for roots and absent ends).

    """
    n, n_joints = present.shape
    lengths = np.full((n, n_joints), np.nan)
    fixes = np.zeros((n_joints, 9))
    unit = np.empty(3)
    for i in range(n):
        held_any = False
        for j in range(n_joints):
            p = parents[j]
            fixes[j, :] = 0.0
            if p < 0 or not (present[i, j] and present[i, p]):
                continue
            length = 0.0
            for k in range(3):
                d = measured[i, j, k] - measured[i, p, k]
                length += d * d
            length = np.sqrt(length)
            lengths[i, j] = length
            if not abs(length - previous_lengths[i, j]) <= _SAME_LENGTH * length:
                continue
            norm = 0.0
            for k in range(3):
                unit[k] = states[0, i, j, k] - states[0, i, p, k]
                norm += unit[k] * unit[k]
            norm = np.sqrt(norm)
            if not norm > _EPS:
                continue
            held_any = True
            along = 0.0
            along_acceleration = 0.0
            for k in range(3):
                unit[k] /= norm
                along += (states[1, i, j, k] - states[1, i, p, k]) * unit[k]
                along_acceleration += (states[2, i, j, k] - states[2, i, p, k]) * unit[k]
            perpendicular = 0.0
            for k in range(3):
                v = states[1, i, j, k] - states[1, i, p, k] - along * unit[k]
                perpendicular += v * v
            centripetal = -perpendicular / length
            for k in range(3):
                fixes[j, k] = (length - norm) * unit[k]
                fixes[j, 3 + k] = -along * unit[k]
                fixes[j, 6 + k] = (centripetal - along_acceleration) * unit[k]
        if not held_any:
            continue
        # Root -> leaves: each joint moves with the corrections of the links above it.
        for j in order:
            p = parents[j]
            if p >= 0:
                for c in range(9):
                    fixes[j, c] += fixes[p, c]
        mean = np.zeros(9)
        count = 0
        for j in range(n_joints):
            if present[i, j]:
                count += 1
                for c in range(9):
                    mean[c] += fixes[j, c]
        for c in range(9):
            mean[c] /= max(count, 1)
        for j in range(n_joints):
            for quantity in range(3):
                for k in range(3):
                    c = 3 * quantity + k
                    states[quantity, i, j, k] += fixes[j, c] - mean[c]
    return lengths


@njit(cache=True)
def smooth_orientations(markers, present, rows, dt, orientations):
    """``Filter._smooth_orientations`` of running tracks (``dt`` known), in place.

    ``markers`` ``(n, J, 20)`` are the output rows; ``orientations`` is the tracks'
    ``kernel_args.OrientationState``.
    """
    quaternions, velocities = orientations.quaternions, orientations.velocities
    accelerations, cutoff = orientations.accelerations, orientations.cutoff
    n, n_joints = present.shape
    unit = np.empty(4)
    end = np.empty(4)
    turned = np.empty(4)
    velocity = np.empty(3)
    for i in range(n):
        s = rows[i]
        step = dt[i]
        weight = 1.0 - np.exp(-2.0 * np.pi * cutoff * step)
        for j in range(n_joints):
            norm = 0.0
            for k in range(4):
                norm += markers[i, j, 4 + k] ** 2
            norm = np.sqrt(norm)
            if not (present[i, j] and norm > 0.5):  # NaN fails too
                continue
            carry = True
            for k in range(4):
                unit[k] = markers[i, j, 4 + k] / norm
                carry = carry and np.isfinite(quaternions[s, j, k])
            if not carry:  # (re)starting joint: the measurement, no angular rates yet
                for k in range(4):
                    quaternions[s, j, k] = unit[k]
                for k in range(3):
                    velocities[s, j, k] = np.nan
                    accelerations[s, j, k] = np.nan
            else:
                # slerp from the previous output towards the measurement, the short way
                dot = 0.0
                for k in range(4):
                    dot += quaternions[s, j, k] * unit[k]
                sign = -1.0 if dot < 0 else 1.0
                for k in range(4):
                    end[k] = sign * unit[k]
                angle = np.arccos(min(max(abs(dot), 0.0), 1.0))
                sine = np.sin(angle)
                if sine < 1e-6:
                    first, second = 1.0 - weight, weight
                else:
                    first = np.sin((1.0 - weight) * angle) / sine
                    second = np.sin(weight * angle) / sine
                size = 0.0
                for k in range(4):
                    turned[k] = first * quaternions[s, j, k] + second * end[k]
                    size += turned[k] ** 2
                size = np.sqrt(size)
                for k in range(4):
                    turned[k] /= size
                # rotation vector of turned ⊗ conj(previous), over dt
                x0, y0, z0, w0 = (
                    quaternions[s, j, 0],
                    quaternions[s, j, 1],
                    quaternions[s, j, 2],
                    (quaternions[s, j, 3]),
                )
                x1, y1, z1, w1 = turned[0], turned[1], turned[2], turned[3]
                w = w1 * w0 + x1 * x0 + y1 * y0 + z1 * z0
                velocity[0] = x1 * w0 - w1 * x0 - y1 * z0 + z1 * y0
                velocity[1] = y1 * w0 - w1 * y0 - z1 * x0 + x1 * z0
                velocity[2] = z1 * w0 - w1 * z0 - x1 * y0 + y1 * x0
                if w < 0:
                    for k in range(3):
                        velocity[k] = -velocity[k]
                sine = np.sqrt(velocity[0] ** 2 + velocity[1] ** 2 + velocity[2] ** 2)
                turn = 2.0 * np.arctan2(sine, abs(w))
                scale = turn / sine if sine > 1e-12 else 2.0
                for k in range(3):
                    rate = velocity[k] * scale / step
                    previous_rate = velocities[s, j, k]
                    accelerations[s, j, k] = (
                        (rate - previous_rate) / step if np.isfinite(previous_rate) else 0.0
                    )
                    velocities[s, j, k] = rate
                for k in range(4):
                    quaternions[s, j, k] = turned[k]
            for k in range(4):
                markers[i, j, 4 + k] = quaternions[s, j, k]
            for k in range(3):
                markers[i, j, 11 + k] = velocities[s, j, k]
                markers[i, j, 17 + k] = accelerations[s, j, k]


@njit(cache=True)
def filter_step(kalman, model, tracks, frame, lengths, orientations, link_ends):
    """``Filter._step`` in Kalman mode for a frame's running tracks, one call (same numbers).

    Args:
        kalman: ``kernel_args.KalmanState`` of the ``KalmanBank`` (updated in place).
        model: ``kernel_args.KalmanModel``, its constants.
        tracks: ``kernel_args.TrackStamps``: the tracks' slots and stamps (updated in place).
        frame: ``kernel_args.FrameRows``: the input rows, which become the output rows in place.
        lengths: ``kernel_args.LengthState``: whether to keep link lengths, the layout's tree
            and the tracks' previous input lengths (updated in place).
        orientations: ``kernel_args.OrientationState`` (updated in place).
        link_ends: ``kernel_args.LinkEnds`` of the layout's links.

    Returns:
        ``(n, J, 20)`` link rows and ``(n, J)`` link presence of the output rows.

    """
    x, P, scale = kalman.x, kalman.P, kalman.scale
    rows, stamps, present = tracks.rows, frame.stamps, frame.present
    time_ns, joint_time_ns = tracks.time_ns, tracks.joint_time_ns
    markers = frame.markers
    n, n_joints = present.shape
    dt = np.empty(n)
    for i in range(n):
        dt[i] = (stamps[i] - time_ns[rows[i]]) * 1e-9
    measured = markers[:, :, 1:4].copy()
    restart = np.zeros((n, n_joints), dtype=np.bool_)
    for i in range(n):
        for j in range(n_joints):
            gap = stamps[i] - joint_time_ns[rows[i], j]
            restart[i, j] = present[i, j] and gap > tracks.max_gap_ns
    corrected = present & ~restart
    kalman_step(kalman, model, KalmanFrame(rows, dt, np.round(dt, 6), corrected, measured))
    states = np.empty((3, n, n_joints, 3))  # positions, velocities, accelerations
    for i in range(n):
        s = rows[i]
        for j in range(n_joints):
            if restart[i, j]:  # KalmanBank.reset: at rest on the measurement
                x[s, :, :, j] = 0.0
                x[s, 0, :, j] = measured[i, j]
                P[s, :, :, j] = model.initial
                scale[s, j] = 1.0
            if present[i, j]:
                joint_time_ns[s, j] = stamps[i]
            for quantity in range(3):
                for axis in range(3):
                    states[quantity, i, j, axis] = x[s, quantity, axis, j]
    if lengths.keep:
        last_lengths = lengths.last_lengths
        input_lengths = keep_lengths(
            lengths.parents, lengths.order, states, measured, present, last_lengths[rows]
        )
        for i in range(n):
            last_lengths[rows[i]] = input_lengths[i]
    for i in range(n):
        time_ns[rows[i]] = stamps[i]
    smooth_orientations(markers, present, rows, dt, orientations)
    for i in range(n):
        for j in range(n_joints):
            if present[i, j]:
                for axis in range(3):
                    markers[i, j, 1 + axis] = states[0, i, j, axis]
                    markers[i, j, 8 + axis] = states[1, i, j, axis]
                    markers[i, j, 14 + axis] = states[2, i, j, axis]
    return _link_rows(markers, present, link_ends.parents, link_ends.children)


refresh_stale_caches(globals())  # the kernels above call hiros_core.compiled's _link_rows
