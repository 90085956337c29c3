"""Compiled fusion kernel of the merger (numba): one call per output instead of ~150 numpy calls.

A merged frame holds a few tracks of a few detections of 32 joints: numpy's per-call overhead
dominated. ``fuse`` computes what ``Merger._fuse`` did with numpy, step for step (same
formulas, NaN rules and, where it matters for equal results, the same summation order: sums
over cameras run in camera order, sums over joints pairwise as numpy's are).

Compiled lazily on first call and cached on disk (``cache=True``): importing this module
compiles nothing. Shapes: ``N`` detections, ``M`` tracks, ``C`` slots per track, ``J`` joints.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hiros_core.compiled import _link_rows, refresh_stale_caches

__all__ = ["follow_directions", "fuse", "merge"]


@njit(cache=True, error_model="numpy")
def _pairwise_sum(values: np.ndarray, n: int) -> float:
    """Sum of ``values[:n]`` in numpy's order for a contiguous reduction (n <= 128)."""
    if n < 8:
        total = 0.0
        for i in range(n):
            total += values[i]
        return total
    r = values[:8].copy()
    i = 8
    while i < n - n % 8:
        for k in range(8):
            r[k] += values[i + k]
        i += 8
    total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        total += values[i]
        i += 1
    return total


@njit(cache=True, error_model="numpy")
def _power(x: float, exponent: float) -> float:
    """``x ** exponent`` as numpy's array power rounds it (squares exactly, 1 as is)."""
    if exponent == 2.0:
        return x * x
    if exponent == 1.0:
        return x
    return math.pow(x, exponent)


@njit(cache=True, error_model="numpy")
def _unit3(x: float, y: float, z: float) -> tuple[float, float, float]:
    norm = math.sqrt(x * x + y * y + z * z)
    return x / norm, y / norm, z / norm


@njit(cache=True, error_model="numpy")
def _robust(  # noqa: PLR0917 - scalars of one reweighting
    weight: np.ndarray,
    residual: np.ndarray,
    own: np.ndarray,
    m: int,
    j: int,
    outlier_scale: float,
    outlier_cutoff: float,
    own_cutoff: float,
    out: np.ndarray,
) -> None:
    """Cauchy reweighting of joint ``j`` of track ``m`` into ``out`` ``(C,)``.

    The Cauchy weight is of ``residual`` (the joint's own, or its limb's mean); nothing whose
    ``residual`` is beyond ``outlier_cutoff`` or ``own`` (the joint's, or its limb's farthest
    joint's) beyond ``own_cutoff``, unless nothing is left.
    """
    n_slots = weight.shape[1]
    inside_total = 0.0
    for c in range(n_slots):
        r = residual[m, c, j]
        scaled = r / outlier_scale
        robust = weight[m, c, j] / (1.0 + scaled * scaled)
        if not math.isfinite(r):
            robust = 0.0
        out[c] = robust
        if r <= outlier_cutoff and own[m, c, j] <= own_cutoff:
            inside_total += robust
    if inside_total > 0:
        for c in range(n_slots):
            if not (residual[m, c, j] <= outlier_cutoff and own[m, c, j] <= own_cutoff):
                out[c] = 0.0


@njit(cache=True, error_model="numpy")
def _residuals(positions: np.ndarray, fused: np.ndarray, residual: np.ndarray) -> None:
    n_tracks, n_slots, n_joints = positions.shape[:3]
    for m in range(n_tracks):
        for c in range(n_slots):
            for j in range(n_joints):
                dx = positions[m, c, j, 0] - fused[m, j, 0]
                dy = positions[m, c, j, 1] - fused[m, j, 1]
                dz = positions[m, c, j, 2] - fused[m, j, 2]
                residual[m, c, j] = math.sqrt(dx * dx + dy * dy + dz * dz)


@njit(cache=True, error_model="numpy")
def _judged_residuals(  # noqa: PLR0917
    positions: np.ndarray,
    fused: np.ndarray,
    finite: np.ndarray,
    groups: np.ndarray,
    limb_residuals: bool,
    residual: np.ndarray,
    limb: np.ndarray,
    peak: np.ndarray,
) -> None:
    """Each detection's joint distances to ``fused``, and what the weights judge them by.

    ``limb``/``peak``: the mean/max over each joint's limb with ``limb_residuals``, else the
    joint's own distance in both.
    """
    _residuals(positions, fused, residual)
    if limb_residuals:
        _limb_means(residual, finite, groups, limb, peak)
    else:
        limb[:] = residual
        peak[:] = residual


@njit(cache=True, error_model="numpy")
def _limb_means(
    values: np.ndarray, finite: np.ndarray, groups: np.ndarray, out: np.ndarray, peak: np.ndarray
) -> None:
    """``out[m, c, j]`` mean and ``peak[m, c, j]`` max of ``values[m, c, k]`` over j's limb.

    Over the finite joints k of the limb (``groups``) in that detection; a joint that is not
    finite keeps its own value in both.
    """
    n_tracks, n_slots, n_joints = values.shape
    n_groups = 0
    for j in range(n_joints):
        n_groups = max(n_groups, groups[j] + 1)
    sums = np.zeros(n_groups)
    counts = np.zeros(n_groups)
    highest = np.zeros(n_groups)
    for m in range(n_tracks):
        for c in range(n_slots):
            sums[:] = 0.0
            counts[:] = 0.0
            highest[:] = 0.0
            for j in range(n_joints):
                if finite[m, c, j] and math.isfinite(values[m, c, j]):
                    g = groups[j]
                    sums[g] += values[m, c, j]
                    counts[g] += 1.0
                    highest[g] = max(highest[g], values[m, c, j])
            for j in range(n_joints):
                g = groups[j]
                if finite[m, c, j] and counts[g] > 0:
                    out[m, c, j] = sums[g] / counts[g]
                    peak[m, c, j] = highest[g]
                else:
                    out[m, c, j] = values[m, c, j]
                    peak[m, c, j] = values[m, c, j]


@njit(cache=True, error_model="numpy")
def _weighted_median(positions: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Per coordinate, the smallest value whose cumulative weight reaches half the total."""
    n_tracks, n_slots, n_joints = positions.shape[:3]
    fused = np.empty((n_tracks, n_joints, 3))
    keys = np.empty(n_slots)
    weights = np.empty(n_slots)
    for m in range(n_tracks):
        for j in range(n_joints):
            for a in range(3):
                count = 0
                for c in range(n_slots):
                    value = positions[m, c, j, a]
                    w = weight[m, c, j] if math.isfinite(value) else 0.0
                    if w > 0:  # insertion sort of the few weighted values
                        i = count
                        while i > 0 and keys[i - 1] > value:
                            keys[i] = keys[i - 1]
                            weights[i] = weights[i - 1]
                            i -= 1
                        keys[i] = value
                        weights[i] = w
                        count += 1
                total = 0.0
                for i in range(count):
                    total += weights[i]
                if not total > 0:
                    fused[m, j, a] = np.nan
                    continue
                cumulative = 0.0
                for i in range(count):
                    cumulative += weights[i]
                    if cumulative >= 0.5 * total:
                        fused[m, j, a] = keys[i]
                        break
    return fused


@njit(cache=True, error_model="numpy")
def _rays(positions: np.ndarray, camera: np.ndarray, radius: float, rays: np.ndarray) -> float:
    """Each joint's unit direction from ``camera`` and distance into ``rays`` ``(J, 4)``.

    Returns the squared distance beyond which a point blocks no joint's ray (see
    ``_occluded``; -1 when no joint is farther than ``radius``).
    """
    reach = -1.0
    for j in range(len(positions)):
        rx = positions[j, 0] - camera[0]
        ry = positions[j, 1] - camera[1]
        rz = positions[j, 2] - camera[2]
        length = math.sqrt(rx * rx + ry * ry + rz * rz)
        rays[j, 0], rays[j, 1], rays[j, 2] = rx / length, ry / length, rz / length
        rays[j, 3] = length
        if length - radius > 0:
            reach = max(reach, (length - radius) ** 2 + radius * radius + 1e-6)
    return reach


@njit(cache=True, error_model="numpy")
def _torso_points(  # noqa: PLR0917
    fused: np.ndarray,
    m: int,
    torso: np.ndarray,
    camera: np.ndarray,
    reach: float,
    points: np.ndarray,
) -> int:
    """Other tracks' torso points ``q - camera`` and their squared norm into ``points``.

    Only those nearer than ``reach`` (squared); returns how many.
    """
    count = 0
    for other in range(len(fused)):
        if other == m:
            continue
        for t in torso:
            qx = fused[other, t, 0] - camera[0]
            qy = fused[other, t, 1] - camera[1]
            qz = fused[other, t, 2] - camera[2]
            squared = qx * qx + qy * qy + qz * qz
            if squared < reach:
                points[count, 0], points[count, 1] = qx, qy
                points[count, 2], points[count, 3] = qz, squared
                count += 1
    return count


@njit(cache=True, error_model="numpy")
def _occluded(  # noqa: PLR0917
    fused: np.ndarray,
    positions: np.ndarray,
    cameras: np.ndarray,
    known: np.ndarray,
    torso: np.ndarray,
    radius: float,
    weight: np.ndarray,
    factor: float,
) -> None:
    """Multiply ``weight`` by ``factor`` where the camera ray passes another track's torso.

    A torso point ``q`` blocks the ray from camera ``o`` to joint ``p`` when it lies within
    ``radius`` of the ray (|rel|² - along² decides, except within 1e-9 m² of the radius where
    the point minus its projection does) and between ``o`` and ``p``. Per detection, only the
    torso points nearer to the camera than ``reach`` are tried: one farther than
    ``sqrt((|p - o| - radius)² + radius²)`` for every joint ``p`` blocks none (the bound has
    1e-6 m² to spare over the test's 1e-9 and its rounding, so the result is the same).
    """
    n_tracks, n_slots, n_joints = positions.shape[:3]
    rays = np.empty((n_joints, 4))  # each joint's unit direction from the camera, distance
    points = np.empty((n_tracks * len(torso), 4))  # torso points near enough: q - o, |q - o|²
    limit = radius * radius
    for m in range(n_tracks):
        for c in range(n_slots):
            if not known[m, c]:
                continue
            reach = _rays(positions[m, c], cameras[m, c], radius, rays)
            count = _torso_points(fused, m, torso, cameras[m, c], reach, points)
            for j in range(n_joints):
                dx, dy, dz, length = rays[j, 0], rays[j, 1], rays[j, 2], rays[j, 3]
                for i in range(count):
                    qx, qy, qz = points[i, 0], points[i, 1], points[i, 2]
                    along = dx * qx + dy * qy + dz * qz
                    across_sq = points[i, 3] - along * along
                    close = across_sq < limit
                    if abs(across_sq - limit) < 1e-9:
                        ex = qx - along * dx
                        ey = qy - along * dy
                        ez = qz - along * dz
                        close = math.sqrt(ex * ex + ey * ey + ez * ez) < radius
                    if close and along > 0 and along < length - radius:
                        weight[m, c, j] *= factor
                        break


@njit(cache=True, error_model="numpy")
def _link_direction(  # noqa: PLR0917 - one link's scalars
    positions: np.ndarray,
    finite: np.ndarray,
    final: np.ndarray,
    m: int,
    j: int,
    p: int,
    iterations: int,
    eps: float,
    units: np.ndarray,
    weights: np.ndarray,
    out: np.ndarray,
) -> bool:
    """Robust mean direction of link ``p -> j`` over the cameras of track ``m`` into ``out``.

    Each camera's unit vector counts with ``sqrt(final[j] · final[p])``; the start is the
    normalised weighted mean, then ``iterations`` Weiszfeld steps on the sphere (weight over
    ``max(angle, eps)``) move it to the weighted spherical median. False: no camera has it.
    """
    n_slots = positions.shape[1]
    total = 0.0
    sx = sy = sz = 0.0
    for c in range(n_slots):
        weights[c] = 0.0
        if not (finite[m, c, j] and finite[m, c, p]):
            continue
        w = math.sqrt(final[m, c, j] * final[m, c, p])
        dx = positions[m, c, j, 0] - positions[m, c, p, 0]
        dy = positions[m, c, j, 1] - positions[m, c, p, 1]
        dz = positions[m, c, j, 2] - positions[m, c, p, 2]
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        if not (w > 0 and norm > 0):
            continue
        units[c, 0], units[c, 1], units[c, 2] = dx / norm, dy / norm, dz / norm
        weights[c] = w
        total += w
        sx += w * units[c, 0]
        sy += w * units[c, 1]
        sz += w * units[c, 2]
    norm = math.sqrt(sx * sx + sy * sy + sz * sz)
    if not (total > 0 and norm > 0):
        return False
    ux, uy, uz = sx / norm, sy / norm, sz / norm
    for _ in range(iterations):
        sx = sy = sz = 0.0
        for c in range(n_slots):
            if weights[c] > 0:
                cx = uy * units[c, 2] - uz * units[c, 1]
                cy = uz * units[c, 0] - ux * units[c, 2]
                cz = ux * units[c, 1] - uy * units[c, 0]
                dot = ux * units[c, 0] + uy * units[c, 1] + uz * units[c, 2]
                angle = math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), dot)
                w = weights[c] / max(angle, eps)
                sx += w * units[c, 0]
                sy += w * units[c, 1]
                sz += w * units[c, 2]
        norm = math.sqrt(sx * sx + sy * sy + sz * sz)
        if not norm > 0:
            break
        ux, uy, uz = sx / norm, sy / norm, sz / norm
    out[0], out[1], out[2] = ux, uy, uz
    return True


@njit(cache=True, error_model="numpy")
def follow_directions(  # noqa: PLR0917 - the fusion's arrays and the layout's
    positions: np.ndarray,
    finite: np.ndarray,
    final: np.ndarray,
    fused: np.ndarray,
    parents: np.ndarray,
    order: np.ndarray,
    groups: np.ndarray,
    iterations: int,
    eps: float,
) -> np.ndarray:
    """Fused skeletons ``(M, J, 3)`` whose links point along the cameras' robust directions.

    Per limb (``groups``), joints are placed root-outward (``order``: parents first): the
    limb's first joint at its fused position, each further joint at its parent plus the fused
    link length (``|fused[j] - fused[p]|``) along the link's robust mean direction over the
    cameras (``_link_direction``, weights ``final`` ``(M, C, J)``); then the limb is shifted so
    that its mean joint is the fused one. A link that no camera sees keeps its fused offset;
    a limb's links across to another limb are not rebuilt (the limbs are placed apart).
    """
    n_tracks, n_slots, n_joints = positions.shape[:3]
    n_groups = 0
    for j in range(n_joints):
        n_groups = max(n_groups, groups[j] + 1)
    out = fused.copy()
    units = np.empty((n_slots, 3))
    weights = np.empty(n_slots)
    direction = np.empty(3)
    shift = np.zeros((n_groups, 3))
    counts = np.zeros(n_groups)
    for m in range(n_tracks):
        for k in range(n_joints):
            j = order[k]
            p = parents[j]
            if p < 0 or groups[p] != groups[j]:
                continue
            dx = fused[m, j, 0] - fused[m, p, 0]
            dy = fused[m, j, 1] - fused[m, p, 1]
            dz = fused[m, j, 2] - fused[m, p, 2]
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            if not math.isfinite(length):
                continue
            if _link_direction(
                positions, finite, final, m, j, p, iterations, eps, units, weights, direction
            ):
                dx, dy, dz = length * direction[0], length * direction[1], length * direction[2]
            out[m, j, 0] = out[m, p, 0] + dx
            out[m, j, 1] = out[m, p, 1] + dy
            out[m, j, 2] = out[m, p, 2] + dz
        shift[:] = 0.0
        counts[:] = 0.0
        for j in range(n_joints):
            if math.isfinite(fused[m, j, 0]) and math.isfinite(out[m, j, 0]):
                g = groups[j]
                counts[g] += 1.0
                for a in range(3):
                    shift[g, a] += fused[m, j, a] - out[m, j, a]
        for j in range(n_joints):
            g = groups[j]
            if counts[g] > 0:
                for a in range(3):
                    out[m, j, a] += shift[g, a] / counts[g]
    return out


@njit(cache=True, error_model="numpy")
def fuse(  # noqa: PLR0912, PLR0915, PLR0917 - one output's whole fusion
    rows: np.ndarray,
    present: np.ndarray,
    table: np.ndarray,
    ages: np.ndarray,
    cameras: np.ndarray,
    agreement: np.ndarray,
    params: np.ndarray,
    iterations: int,
    extrapolate: bool,
    root: int,
    neck: int,
    left: np.ndarray,
    right: np.ndarray,
    torso: np.ndarray,
    pointers: np.ndarray,
    has_front: bool,
    groups: np.ndarray,
    limb_residuals: bool,
    parents: np.ndarray,
    order: np.ndarray,
    directions: bool,
    direction_iterations: int,
    direction_eps: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fuse the detections of every track (see ``Merger._fuse`` for the weights).

    Detection ``c`` of track ``m`` is slot ``table[m, c]`` (-1: padding) of the stored
    ``rows`` ``(S, J', 20)`` and ``present`` ``(S, J')`` (``J' >= J``, the layout's
    ``len(groups)``); ``ages`` ``(M, C)`` seconds to the output time, ``cameras`` ``(M, C, 3)``
    camera positions (NaN unknown), ``agreement`` ``(M, C)`` each camera's agreement factor;
    ``params`` the float parameters in the order of ``Merger._kernel_constants``; the layout's
    ``root``, ``neck``, ``left``/``right`` (hip, shoulder), ``torso`` and forward ``pointers``
    joints; with ``directions`` the fused skeletons follow the cameras' robust link
    directions (``follow_directions``, over the layout's ``parents`` in ``order``).

    Returns:
        ``fused`` ``(M, J, 3)``, ``final`` ``(M, C, J)`` weights, ``confidence`` ``(M, J)`` and
        ``velocity`` ``(M, J, 3)`` weighted means, and ``(M, C)`` each detection's mean joint
        distance to the fused skeleton (residuals capped at 0.5 m; NaN where it has no joint).

    """
    (
        max_extrapolation,
        confidence_floor,
        confidence_power,
        staleness_scale,
        depth_gain,
        flipped_weight,
        view_weight_min,
        view_power,
        occlusion_radius,
        occlusion_weight,
        outlier_scale,
        outlier_cutoff,
        limb_cutoff,
        oblique_gain,
    ) = (
        params[0],
        params[1],
        params[2],
        params[3],
        params[4],
        params[5],
        params[6],
        params[7],
        params[8],
        params[9],
        params[10],
        params[11],
        params[12],
        params[13],
    )
    own_cutoff = limb_cutoff if limb_residuals else outlier_cutoff
    n_tracks, n_slots = table.shape
    n_joints = len(groups)
    known = np.zeros((n_tracks, n_slots), dtype=np.bool_)
    any_known = False
    for m in range(n_tracks):
        for c in range(n_slots):
            known[m, c] = (
                math.isfinite(cameras[m, c, 0])
                and math.isfinite(cameras[m, c, 1])
                and math.isfinite(cameras[m, c, 2])
            )
            any_known = any_known or known[m, c]

    # Positions brought to the output time, and the weights known before fusing.
    # (An absent joint or a padding slot reads as a NaN row.)
    positions = np.empty((n_tracks, n_slots, n_joints, 3))
    velocities = np.empty((n_tracks, n_slots, n_joints, 3))
    finite = np.zeros((n_tracks, n_slots, n_joints), dtype=np.bool_)
    weight = np.zeros((n_tracks, n_slots, n_joints))
    confidences = np.empty((n_tracks, n_slots, n_joints))
    for m in range(n_tracks):
        for c in range(n_slots):
            s = table[m, c]
            dt = min(max(ages[m, c], -max_extrapolation), max_extrapolation)
            stale = ages[m, c] / staleness_scale
            for j in range(n_joints):
                valid = s >= 0 and present[s, j]
                for a in range(3):
                    p = rows[s, j, 1 + a] if valid else np.nan
                    v = rows[s, j, 8 + a] if valid else np.nan
                    velocities[m, c, j, a] = v
                    if extrapolate:
                        p = p + (v if math.isfinite(v) else 0.0) * dt
                    positions[m, c, j, a] = p
                is_finite = (
                    math.isfinite(positions[m, c, j, 0])
                    and math.isfinite(positions[m, c, j, 1])
                    and math.isfinite(positions[m, c, j, 2])
                )
                finite[m, c, j] = is_finite
                confidence = rows[s, j, 0] if valid else np.nan
                confidence = confidence if math.isfinite(confidence) else 1.0
                confidences[m, c, j] = confidence
                w = _power(max(confidence, confidence_floor), confidence_power)
                if not is_finite:
                    w = 0.0
                w = w / (1.0 + stale * stale)
                w = w * agreement[m, c]
                if known[m, c]:
                    dx = positions[m, c, j, 0] - cameras[m, c, 0]
                    dy = positions[m, c, j, 1] - cameras[m, c, 1]
                    dz = positions[m, c, j, 2] - cameras[m, c, 2]
                    depth = math.sqrt(dx * dx + dy * dy + dz * dz)
                    w = w * math.pow(1.0 + depth_gain * depth, -2.0)
                weight[m, c, j] = w

    fused = _weighted_median(positions, weight)
    if has_front:
        for m in range(n_tracks):
            ux, uy, uz = _unit3(
                fused[m, neck, 0] - fused[m, root, 0],
                fused[m, neck, 1] - fused[m, root, 1],
                fused[m, neck, 2] - fused[m, root, 2],
            )
            side = np.zeros(3)
            for a in range(3):
                total = 0.0
                for i in range(len(left)):
                    total += fused[m, left[i], a]
                other = 0.0
                for i in range(len(right)):
                    other += fused[m, right[i], a]
                side[a] = total / len(left) - other / len(right)
            fx, fy, fz = _unit3(
                side[1] * uz - side[2] * uy,
                side[2] * ux - side[0] * uz,
                side[0] * uy - side[1] * ux,
            )
            for c in range(n_slots):
                if len(pointers):
                    sx = sy = sz = 0.0
                    for i in range(len(pointers)):
                        a, b = pointers[i, 0], pointers[i, 1]
                        px = positions[m, c, b, 0] - positions[m, c, a, 0]
                        py = positions[m, c, b, 1] - positions[m, c, a, 1]
                        pz = positions[m, c, b, 2] - positions[m, c, a, 2]
                        along = px * ux + py * uy + pz * uz
                        px, py, pz = _unit3(px - along * ux, py - along * uy, pz - along * uz)
                        sx += px if math.isfinite(px) else 0.0
                        sy += py if math.isfinite(py) else 0.0
                        sz += pz if math.isfinite(pz) else 0.0
                    sx, sy, sz = _unit3(sx, sy, sz)
                    if sx * fx + sy * fy + sz * fz < 0:
                        for j in range(n_joints):
                            weight[m, c, j] = weight[m, c, j] * flipped_weight
                if any_known and known[m, c]:
                    tx = cameras[m, c, 0] - fused[m, root, 0]
                    ty = cameras[m, c, 1] - fused[m, root, 1]
                    tz = cameras[m, c, 2] - fused[m, root, 2]
                    tx, ty, tz = _unit3(tx, ty, tz)
                    cosine = fx * tx + fy * ty + fz * tz
                    view = _power((1.0 + cosine) / 2.0, view_power)
                    if math.isfinite(view):  # (a NaN view leaves the weight as it is)
                        view = max(view, view_weight_min)
                        if oblique_gain > 0:
                            sine = math.sqrt(max(1.0 - cosine * cosine, 0.0))
                            view = view / _power(1.0 + oblique_gain * sine, 2.0)
                        for j in range(n_joints):
                            weight[m, c, j] = weight[m, c, j] * view
    if occlusion_radius > 0 and n_tracks > 1 and any_known:
        _occluded(
            fused, positions, cameras, known, torso, occlusion_radius, weight, occlusion_weight
        )

    # Robust mean: Cauchy reweighting around the current estimate, a few times; with
    # ``limb_residuals`` the Cauchy weight is of the mean residual over the joint's limb
    # (``groups``) in that detection, so a camera's limb is weighed and kept or dropped whole;
    # a limb one of whose joints is beyond ``limb_cutoff`` is dropped.
    residual = np.empty((n_tracks, n_slots, n_joints))
    limb = np.empty((n_tracks, n_slots, n_joints))
    peak = np.empty((n_tracks, n_slots, n_joints))
    robust = np.empty(n_slots)
    for _ in range(iterations):
        _judged_residuals(positions, fused, finite, groups, limb_residuals, residual, limb, peak)
        for m in range(n_tracks):
            for j in range(n_joints):
                _robust(weight, limb, peak, m, j, outlier_scale, outlier_cutoff, own_cutoff, robust)
                total = 0.0
                sx = sy = sz = 0.0
                for c in range(n_slots):
                    w = robust[c] if finite[m, c, j] else 0.0
                    total += w
                    if finite[m, c, j]:
                        sx += positions[m, c, j, 0] * w
                        sy += positions[m, c, j, 1] * w
                        sz += positions[m, c, j, 2] * w
                fused[m, j, 0] = sx / total if total != 0 else np.nan
                fused[m, j, 1] = sy / total if total != 0 else np.nan
                fused[m, j, 2] = sz / total if total != 0 else np.nan
    _judged_residuals(positions, fused, finite, groups, limb_residuals, residual, limb, peak)
    final = np.empty((n_tracks, n_slots, n_joints))
    confidence = np.empty((n_tracks, n_joints))
    velocity = np.empty((n_tracks, n_joints, 3))
    for m in range(n_tracks):
        for j in range(n_joints):
            _robust(weight, limb, peak, m, j, outlier_scale, outlier_cutoff, own_cutoff, robust)
            total_c = total_v = 0.0
            mean_c = 0.0
            vx = vy = vz = 0.0
            for c in range(n_slots):
                w = robust[c]
                final[m, c, j] = w
                if w > 0:
                    total_c += w
                    mean_c += confidences[m, c, j] * w
                v0, v1, v2 = velocities[m, c, j, 0], velocities[m, c, j, 1], velocities[m, c, j, 2]
                if math.isfinite(v0) and math.isfinite(v1) and math.isfinite(v2):
                    total_v += w
                    vx += v0 * w
                    vy += v1 * w
                    vz += v2 * w
            confidence[m, j] = mean_c / total_c if total_c != 0 else np.nan
            velocity[m, j, 0] = vx / total_v if total_v != 0 else np.nan
            velocity[m, j, 1] = vy / total_v if total_v != 0 else np.nan
            velocity[m, j, 2] = vz / total_v if total_v != 0 else np.nan

    # Each detection's agreement with the fused skeleton: mean capped residual over its joints.
    disagreement = np.full((n_tracks, n_slots), np.nan)
    capped = np.empty(n_joints)
    for m in range(n_tracks):
        for c in range(n_slots):
            count = 0
            for j in range(n_joints):
                r = residual[m, c, j]
                if math.isfinite(r):
                    capped[j] = min(r, 0.5)
                    count += 1
                else:
                    capped[j] = 0.0
            if count:
                disagreement[m, c] = _pairwise_sum(capped, n_joints) / count
    if directions:
        fused = follow_directions(
            positions,
            finite,
            final,
            fused,
            parents,
            order,
            groups,
            direction_iterations,
            direction_eps,
        )
    return fused, final, confidence, velocity, disagreement


@njit(cache=True, error_model="numpy")
def _arrange(tracks: np.ndarray, selected: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted track ids ``(M,)`` of the ``selected`` slots, and their ``(M, C)`` slot table.

    Row ``m`` holds track ``m``'s slots in their order in ``selected``, then -1 padding.
    """
    track_ids = np.unique(tracks[selected])
    rows_of = np.searchsorted(track_ids, tracks[selected])
    counts = np.zeros(len(track_ids), dtype=np.int64)
    for m in rows_of:
        counts[m] += 1
    table = np.full((len(track_ids), counts.max()), -1, dtype=np.int64)
    counts[:] = 0
    for i in range(len(selected)):
        m = rows_of[i]
        table[m, counts[m]] = selected[i]
        counts[m] += 1
    return track_ids, table


@njit(cache=True, error_model="numpy")
def _detection_terms(  # noqa: PLR0917
    table: np.ndarray,
    stamps: np.ndarray,
    cameras: np.ndarray,
    out_ns: int,
    camera_positions: np.ndarray,
    camera_factors: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each detection's age (s), camera position and agreement factor, ``(M, C)``-padded.

    Padding: age 0, position NaN (unknown camera), factor 1.
    """
    n_tracks, n_slots = table.shape
    ages = np.zeros((n_tracks, n_slots))
    where = np.full((n_tracks, n_slots, 3), np.nan)
    agreement = np.ones((n_tracks, n_slots))
    for m in range(n_tracks):
        for c in range(n_slots):
            s = table[m, c]
            if s >= 0:
                ages[m, c] = (out_ns - stamps[s]) * 1e-9
                where[m, c] = camera_positions[cameras[s]]
                agreement[m, c] = camera_factors[cameras[s]]
    return ages, where, agreement


@njit(cache=True, error_model="numpy")
def _output_rows(
    fused: np.ndarray, confidence: np.ndarray, velocity: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Marker rows ``(M, J, 20)``, presence ``(M, J)`` and skeleton confidence ``(M,)``.

    A joint is present where its fused position is finite; its row holds the confidence,
    position and velocity (NaN elsewhere). A skeleton's confidence is the mean of its present
    joints' non-NaN confidences, summed as numpy's ``nanmean`` sums them (NaN: none).
    """
    n_tracks, n_joints = confidence.shape
    rows = np.full((n_tracks, n_joints, 20), np.nan)
    present = np.zeros((n_tracks, n_joints), dtype=np.bool_)
    skeleton = np.full(n_tracks, np.nan)
    values = np.empty(n_joints)
    for m in range(n_tracks):
        n_present = n_valued = 0
        for j in range(n_joints):
            if not (
                math.isfinite(fused[m, j, 0])
                and math.isfinite(fused[m, j, 1])
                and math.isfinite(fused[m, j, 2])
            ):
                continue
            present[m, j] = True
            rows[m, j, 0] = confidence[m, j]
            for a in range(3):
                rows[m, j, 1 + a] = fused[m, j, a]
                rows[m, j, 8 + a] = velocity[m, j, a]
            valued = not math.isnan(confidence[m, j])
            values[n_present] = confidence[m, j] if valued else 0.0
            n_present += 1
            if valued:
                n_valued += 1
        if n_valued:
            skeleton[m] = _pairwise_sum(values, n_present) / n_valued
    return rows, present, skeleton


@njit(cache=True, error_model="numpy")
def _camera_errors(
    disagreement: np.ndarray, table: np.ndarray, cameras: np.ndarray, n_cameras: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per camera index, the sum (in track order) and count of its detections' disagreements."""
    totals = np.zeros(n_cameras)
    counts = np.zeros(n_cameras, dtype=np.int64)
    n_tracks, n_slots = table.shape
    for m in range(n_tracks):
        for c in range(n_slots):
            s = table[m, c]
            if s >= 0 and not math.isnan(disagreement[m, c]):
                totals[cameras[s]] += disagreement[m, c]
                counts[cameras[s]] += 1
    return totals, counts


@njit(cache=True, error_model="numpy")
def _any_orientation(rows: np.ndarray, present: np.ndarray, selected: np.ndarray, n: int) -> bool:
    """Whether a present joint (of the first ``n``) of a ``selected`` slot has an orientation."""
    for s in selected:
        for j in range(n):
            if (
                present[s, j]
                and math.isfinite(rows[s, j, 4])
                and math.isfinite(rows[s, j, 5])
                and math.isfinite(rows[s, j, 6])
                and math.isfinite(rows[s, j, 7])
            ):
                return True
    return False


@njit(cache=True, error_model="numpy")
def merge(  # noqa: PLR0917 - the stored detections, the cameras, the parameters, the layout
    rows: np.ndarray,
    present: np.ndarray,
    stamps: np.ndarray,
    tracks: np.ndarray,
    cameras: np.ndarray,
    selected: np.ndarray,
    out_ns: int,
    camera_positions: np.ndarray,
    camera_factors: np.ndarray,
    params: np.ndarray,
    iterations: int,
    extrapolate: bool,
    root: int,
    neck: int,
    left: np.ndarray,
    right: np.ndarray,
    torso: np.ndarray,
    pointers: np.ndarray,
    has_front: bool,
    groups: np.ndarray,
    limb_residuals: bool,
    parents: np.ndarray,
    order: np.ndarray,
    directions: bool,
    direction_iterations: int,
    direction_eps: float,
    link_parents: np.ndarray,
    link_children: np.ndarray,
) -> tuple[
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    bool,
]:
    """One output: ``fuse`` the ``selected`` stored slots at ``out_ns``, as output rows.

    The slots' ``rows``/``present``/``stamps``/``tracks``/``cameras`` are the stored
    detections' (``LatestDetections``); ``camera_positions`` ``(K, 3)`` (NaN unknown) and
    ``camera_factors`` ``(K,)`` (agreement) by camera index; the rest as ``fuse`` takes them.

    Returns:
        ``track_ids`` ``(M,)`` sorted, ``table`` ``(M, C)`` each track's slots (-1 padding),
        ``final`` ``(M, C, J)`` weights, output ``rows`` ``(M, J, 20)``, ``present``
        ``(M, J)``, their link rows and presence (``model.link_rows``' over the layout's
        ``link_parents``/``link_children``) and skeleton confidences ``(M,)``
        (``_output_rows``), per camera index the
        sum and count of its detections' mean joint distances to the fused skeletons, and
        whether any selected joint has an orientation (to average, outside).

    """
    track_ids, table = _arrange(tracks, selected)
    ages, where, agreement = _detection_terms(
        table, stamps, cameras, out_ns, camera_positions, camera_factors
    )
    fused, final, confidence, velocity, disagreement = fuse(
        rows, present, table, ages, where, agreement, params, iterations, extrapolate, root,
        neck, left, right, torso, pointers, has_front, groups, limb_residuals, parents, order,
        directions, direction_iterations, direction_eps,
    )  # fmt: skip
    out_rows, out_present, skeleton = _output_rows(fused, confidence, velocity)
    links, link_present = _link_rows(out_rows, out_present, link_parents, link_children)
    totals, counts = _camera_errors(disagreement, table, cameras, len(camera_factors))
    oriented = _any_orientation(rows, present, selected, len(groups))
    return (
        track_ids, table, final, out_rows, out_present, links, link_present, skeleton, totals,
        counts, oriented,
    )  # fmt: skip


refresh_stale_caches(globals())  # the kernels above call hiros_core.compiled's _link_rows
