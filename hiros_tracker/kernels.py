"""Compiled per-frame kernels of the tracker (numba): one call where numpy needed dozens.

A tracker frame holds a handful of people and 32 joints: numpy's per-call overhead (1-5 us)
dominated the arithmetic, so each step of ``Tracker._process`` that took many small numpy calls
is one loop nest here. Each kernel computes what the numpy form in ``tracker.py``'s history did
(same formulas, same NaN rules; sums may round in a different order, ~1e-16).

Compiled lazily on first call and cached on disk (``cache=True``): importing this module
compiles nothing. Shapes as in ``tracker.py``: ``T`` tracks, ``D`` detections, ``U`` matched
pairs, ``J`` joints, ``K`` mirror parts, ``C`` cameras.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "canonical_poses",
    "facing_evidence",
    "hit_update",
    "label_rows",
    "masked_positions",
    "match_costs",
    "solve_velocities",
]


@njit(cache=True, error_model="numpy")
def masked_positions(
    markers: np.ndarray, present: np.ndarray, min_confidence: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(D, J, 3)`` positions, NaN where absent or below ``min_confidence``; ``(D,)`` usable.

    A detection is usable when one of its present joints has a finite position (whatever
    its confidence). Also returns ``(D,)`` how many joints each keeps (finite positions).
    """
    n_det, n_joints = present.shape
    positions = np.empty((n_det, n_joints, 3))
    usable = np.zeros(n_det, dtype=np.bool_)
    kept = np.zeros(n_det, dtype=np.int64)
    for d in range(n_det):
        for j in range(n_joints):
            x, y, z = markers[d, j, 1], markers[d, j, 2], markers[d, j, 3]
            finite = math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
            if present[d, j] and finite:
                usable[d] = True
            keep = present[d, j] and not (min_confidence > 0 and markers[d, j, 0] < min_confidence)
            if keep:
                positions[d, j, 0], positions[d, j, 1], positions[d, j, 2] = x, y, z
                kept[d] += finite
            else:
                positions[d, j, :] = np.nan
    return positions, usable, kept


@njit(cache=True, error_model="numpy")
def match_costs(  # noqa: PLR0912, PLR0917 - one loop nest, one frame's whole input
    positions: np.ndarray,
    velocity: np.ndarray,
    times_ns: np.ndarray,
    stamp_ns: int,
    max_prediction: float,
    detections: np.ndarray,
    weights: np.ndarray,
    part: np.ndarray,
    mirror: np.ndarray,
    n_parts: int,
    use_parts: bool,
    min_joints: int,
    margin: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Each track predicted to ``stamp_ns``, then the cost of every (track, detection).

    The tracks' poses ``positions`` ``(T, J, 3)`` at ``times_ns`` ``(T,)`` move with their
    body ``velocity`` ``(T, 3)`` for at most ``max_prediction`` seconds either way; each is
    compared with ``detections`` ``(D, J, 3)`` (NaN for joints left out) by the ``weights``
    ``(J,)`` mean of joint distances. With ``use_parts``, each of the ``n_parts`` mirror parts
    (``part`` ``(J,)``: -1 on the midline; ``mirror`` ``(J,)`` the left/right permutation) is
    compared also mirrored and the cheaper labelling kept.

    Returns:
        ``(T, D)`` weighted mean joint distances (``inf`` below ``min_joints`` shared joints)
        and ``(T, D, K)`` the parts taken mirrored (a part's mirror must be cheaper by
        ``margin``, plain mean over its joints).

    """
    n_tracks, n_joints = positions.shape[:2]
    n_det = detections.shape[0]
    cost = np.empty((n_tracks, n_det))
    flips = np.zeros((n_tracks, n_det, n_parts), dtype=np.bool_)
    predicted = np.empty((n_joints, 3))
    as_given = np.empty(n_joints)
    mirrored = np.empty(n_joints)
    sums = np.zeros((2, max(n_parts, 1)))
    counts = np.zeros((2, max(n_parts, 1)))
    for t in range(n_tracks):
        dt = (stamp_ns - times_ns[t]) * 1e-9
        dt = min(max(dt, -max_prediction), max_prediction)
        for j in range(n_joints):
            for a in range(3):
                predicted[j, a] = positions[t, j, a] + velocity[t, a] * dt
        for d in range(n_det):
            for j in range(n_joints):
                dx = predicted[j, 0] - detections[d, j, 0]
                dy = predicted[j, 1] - detections[d, j, 1]
                dz = predicted[j, 2] - detections[d, j, 2]
                as_given[j] = math.sqrt(dx * dx + dy * dy + dz * dz)
            if use_parts:
                sums[:] = 0.0
                counts[:] = 0.0
                for j in range(n_joints):
                    m = mirror[j]
                    dx = predicted[j, 0] - detections[d, m, 0]
                    dy = predicted[j, 1] - detections[d, m, 1]
                    dz = predicted[j, 2] - detections[d, m, 2]
                    mirrored[j] = math.sqrt(dx * dx + dy * dy + dz * dz)
                    k = part[j]
                    if k >= 0:
                        if math.isfinite(as_given[j]):
                            sums[0, k] += as_given[j]
                            counts[0, k] += 1.0
                        if math.isfinite(mirrored[j]):
                            sums[1, k] += mirrored[j]
                            counts[1, k] += 1.0
                for k in range(n_parts):
                    flips[t, d, k] = counts[1, k] > 0 and (
                        sums[1, k] / counts[1, k] + margin < sums[0, k] / max(counts[0, k], 1.0)
                    )
            total = 0.0
            norm = 0.0
            shared = 0
            for j in range(n_joints):
                k = part[j]
                value = mirrored[j] if use_parts and k >= 0 and flips[t, d, k] else as_given[j]
                if math.isfinite(value):
                    total += value * weights[j]
                    norm += weights[j]
                    shared += 1
            if shared < min_joints:
                cost[t, d] = np.inf
            elif norm > 0:
                cost[t, d] = total / norm
            else:
                cost[t, d] = np.nan
    return cost, flips


@njit(cache=True, error_model="numpy")
def _order(flips: np.ndarray, part: np.ndarray, mirror: np.ndarray, out: np.ndarray) -> None:
    """Joint order relabelling the parts flagged in ``flips`` ``(K,)``, written to ``out``."""
    for j in range(len(part)):
        out[j] = mirror[j] if part[j] >= 0 and flips[part[j]] else j


@njit(cache=True, error_model="numpy")
def canonical_poses(  # noqa: PLR0917
    positions: np.ndarray,
    rows: np.ndarray,
    flips: np.ndarray,
    part: np.ndarray,
    mirror: np.ndarray,
    align: bool,
    shoulders: np.ndarray,
    pairs: np.ndarray,
    pair_parts: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Matched detections in their tracks' labelling, hips/eyes/ears put on the shoulders' side.

    ``positions`` ``(D, J, 3)`` are the frame's detections, ``rows`` ``(U,)`` those matched
    and ``flips`` ``(U, K)`` the parts to relabel in each (``part``, ``mirror`` as in
    ``match_costs``; the input is not changed). With ``align``, parts whose left/right pair
    (``pairs`` ``(P, 2)``, of parts ``pair_parts`` ``(P,)``) points against the
    ``shoulders`` ``(2,)`` (cos < -0.5) are flipped too; nothing is flagged where a joint is
    missing, or without shoulders (empty).

    Returns:
        ``(U, J, 3)`` canonical poses and ``(U, K)`` the flips used.

    """
    n_pairs, n_joints = len(rows), positions.shape[1]
    flips = flips.copy()
    canonical = np.empty((n_pairs, n_joints, 3))
    order = np.empty(n_joints, dtype=np.int64)
    for u in range(n_pairs):
        _order(flips[u], part, mirror, order)
        for j in range(n_joints):
            canonical[u, j] = positions[rows[u], order[j]]
        if not align or len(shoulders) < 2 or len(pairs) == 0:
            continue
        sx = canonical[u, shoulders[0], 0] - canonical[u, shoulders[1], 0]
        sy = canonical[u, shoulders[0], 1] - canonical[u, shoulders[1], 1]
        sz = canonical[u, shoulders[0], 2] - canonical[u, shoulders[1], 2]
        shoulder_sq = sx * sx + sy * sy + sz * sz
        changed = False
        for p in range(len(pairs)):
            a, b = pairs[p, 0], pairs[p, 1]
            vx = canonical[u, a, 0] - canonical[u, b, 0]
            vy = canonical[u, a, 1] - canonical[u, b, 1]
            vz = canonical[u, a, 2] - canonical[u, b, 2]
            along = vx * sx + vy * sy + vz * sz
            scale = math.sqrt((vx * vx + vy * vy + vz * vz) * shoulder_sq)
            if along < -0.5 * scale:  # clearly reversed only: eyes must not toggle on noise
                flips[u, pair_parts[p]] = not flips[u, pair_parts[p]]
                changed = True
        if changed:
            _order(flips[u], part, mirror, order)
            for j in range(n_joints):
                canonical[u, j] = positions[rows[u], order[j]]
    return canonical, flips


@njit(cache=True, error_model="numpy")
def hit_update(  # noqa: PLR0917
    positions: np.ndarray,
    velocity: np.ndarray,
    times_ns: np.ndarray,
    epochs_ns: np.ndarray,
    alpha: np.ndarray,
    canonical: np.ndarray,
    time_ns: int,
    max_prediction: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Tracks' new smoothed poses and the velocity-fit terms of their new detections.

    Each track is predicted to ``max(its time, time_ns)``; a measured joint moves by ``alpha``
    towards the detection, an unmeasured one keeps the prediction (or takes the detection
    where the prediction is not finite).

    Returns:
        ``(U, J, 3)`` updated poses and ``(U, J, 9)`` terms n, t, t², p (3), t·p (3) of the
        least-squares slope, ``t`` in seconds from each track's epoch.

    """
    n_pairs, n_joints = canonical.shape[:2]
    updated = np.empty((n_pairs, n_joints, 3))
    terms = np.zeros((n_pairs, n_joints, 9))
    for u in range(n_pairs):
        now = max(times_ns[u], time_ns)
        dt = (now - times_ns[u]) * 1e-9
        dt = min(max(dt, -max_prediction), max_prediction)
        t = (time_ns - epochs_ns[u]) * 1e-9
        for j in range(n_joints):
            measured = (
                math.isfinite(canonical[u, j, 0])
                and math.isfinite(canonical[u, j, 1])
                and math.isfinite(canonical[u, j, 2])
            )
            for a in range(3):
                predicted = positions[u, j, a] + velocity[u, a] * dt
                value = predicted
                if measured:
                    value = predicted + alpha[u] * (canonical[u, j, a] - predicted)
                if not math.isfinite(value):
                    value = canonical[u, j, a]
                updated[u, j, a] = value
            if measured:
                terms[u, j, 0] = 1.0
                terms[u, j, 1] = t
                terms[u, j, 2] = t * t
                for a in range(3):
                    terms[u, j, 3 + a] = canonical[u, j, a]
                    terms[u, j, 6 + a] = canonical[u, j, a] * t
    return updated, terms


@njit(cache=True, error_model="numpy")
def solve_velocities(
    sums: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slopes from per-camera sums ``(U, C, J, 9)``: one intercept per camera (fixed effects).

    Returns ``(U, J, 3)`` joint velocities (0 where undetermined), ``(U, 3)`` body velocities
    pooled with ``weights`` ``(J,)`` and ``(U,)`` whether anything was determined.
    """
    n_pairs, n_cameras, n_joints = sums.shape[:3]
    velocities = np.zeros((n_pairs, n_joints, 3))
    body = np.zeros((n_pairs, 3))
    determined = np.zeros(n_pairs, dtype=np.bool_)
    sxy = np.empty(3)
    for u in range(n_pairs):
        pooled = 0.0
        moment = np.zeros(3)
        for j in range(n_joints):
            sxx = 0.0
            sxy[:] = 0.0
            for c in range(n_cameras):
                n = max(sums[u, c, j, 0], 1.0)
                sxx += sums[u, c, j, 2] - sums[u, c, j, 1] ** 2 / n
                for a in range(3):
                    sxy[a] += sums[u, c, j, 6 + a] - sums[u, c, j, 1] * sums[u, c, j, 3 + a] / n
            if sxx > 1e-5:
                determined[u] = True
                pooled += sxx * weights[j]
                for a in range(3):
                    velocities[u, j, a] = sxy[a] / sxx
                    moment[a] += sxy[a] * weights[j]
        for a in range(3):
            body[u, a] = moment[a] / max(pooled, 1e-12)
    return velocities, body, determined


@njit(cache=True, error_model="numpy")
def _unit3(x: float, y: float, z: float) -> tuple[float, float, float]:
    """A vector scaled to unit length; zero or NaN gives NaN."""
    norm = math.sqrt(x * x + y * y + z * z)
    if norm == 0.0:
        return np.nan, np.nan, np.nan
    return x / norm, y / norm, z / norm


@njit(cache=True, error_model="numpy")
def _flat3(  # noqa: PLR0917 - two vectors as scalars (no arrays in the inner loop)
    x: float, y: float, z: float, ux: float, uy: float, uz: float
) -> tuple[float, float, float]:
    """A vector with its component along the unit ``u`` removed."""
    along = x * ux + y * uy + z * uz
    return x - along * ux, y - along * uy, z - along * uz


@njit(cache=True, error_model="numpy")
def trunk_mean(positions: np.ndarray, root: int, neck: int) -> tuple[np.ndarray, int]:
    """``(3,)`` mean unit root -> neck over the poses where it is finite, and how many."""
    mean = np.zeros(3)
    count = 0
    for u in range(len(positions)):
        x, y, z = _unit3(
            positions[u, neck, 0] - positions[u, root, 0],
            positions[u, neck, 1] - positions[u, root, 1],
            positions[u, neck, 2] - positions[u, root, 2],
        )
        if math.isfinite(x) and math.isfinite(y) and math.isfinite(z):
            mean[0] += x
            mean[1] += y
            mean[2] += z
            count += 1
    if count:
        mean /= count
    return mean, count


@njit(cache=True, error_model="numpy")
def facing_evidence(  # noqa: PLR0917
    positions: np.ndarray,
    canonical: np.ndarray,
    velocity: np.ndarray,
    up: np.ndarray,
    camera: np.ndarray,
    has_camera: bool,
    root: int,
    left: np.ndarray,
    right: np.ndarray,
    pointers: np.ndarray,
    flip_prior: float,
    flip_prior_back: float,
    walking_speed: float,
    walking_evidence: float,
) -> np.ndarray:
    """``(U,)`` log-odds each detection gives that its track faces the way its sides say.

    ``positions`` ``(U, J, 3)`` the tracks' poses, ``canonical`` their detections, ``velocity``
    ``(U, 3)`` the tracks' body velocities, ``up`` ``(3,)`` the world's up, ``camera`` ``(3,)``
    the camera's position (used when ``has_camera``); see ``Tracker._facing``.
    """
    n_pairs = len(positions)
    evidence = np.zeros(n_pairs)
    ux, uy, uz = up[0], up[1], up[2]
    for u in range(n_pairs):
        lx = ly = lz = 0.0
        for i in range(len(left)):
            lx += positions[u, left[i], 0]
            ly += positions[u, left[i], 1]
            lz += positions[u, left[i], 2]
        rx = ry = rz = 0.0
        for i in range(len(right)):
            rx += positions[u, right[i], 0]
            ry += positions[u, right[i], 1]
            rz += positions[u, right[i], 2]
        lx, ly, lz = lx - rx, ly - ry, lz - rz
        fx, fy, fz = _unit3(ly * uz - lz * uy, lz * ux - lx * uz, lx * uy - ly * ux)
        ax = ay = az = 0.0
        for i in range(len(pointers)):
            a, b = pointers[i, 0], pointers[i, 1]
            sx, sy, sz = _flat3(
                canonical[u, b, 0] - canonical[u, a, 0],
                canonical[u, b, 1] - canonical[u, a, 1],
                canonical[u, b, 2] - canonical[u, a, 2],
                ux,
                uy,
                uz,
            )
            sx, sy, sz = _unit3(sx, sy, sz)
            ax += sx if math.isfinite(sx) else 0.0
            ay += sy if math.isfinite(sy) else 0.0
            az += sz if math.isfinite(sz) else 0.0
        ax, ay, az = _unit3(ax, ay, az)
        flipped = ax * fx + ay * fy + az * fz < 0
        if has_camera:
            cx, cy, cz = _flat3(
                camera[0] - positions[u, root, 0],
                camera[1] - positions[u, root, 1],
                camera[2] - positions[u, root, 2],
                ux,
                uy,
                uz,
            )
            cx, cy, cz = _unit3(cx, cy, cz)
            cosine = fx * cx + fy * cy + fz * cz
            prior_right = flip_prior_back if cosine < -0.5 else flip_prior
            prior_wrong = flip_prior_back if -cosine < -0.5 else flip_prior
            likely_right = prior_right if flipped else 1.0 - prior_right
            likely_wrong = 1.0 - prior_wrong if flipped else prior_wrong
            value = math.log(likely_right / likely_wrong)
        else:  # no camera pose: a flipped-looking detection is simply evidence against
            value = (-1.0 if flipped else 1.0) * math.log((1.0 - flip_prior) / flip_prior)
        wx, wy, wz = _flat3(velocity[u, 0], velocity[u, 1], velocity[u, 2], ux, uy, uz)
        speed = math.sqrt(wx * wx + wy * wy + wz * wz)
        along = (wx * fx + wy * fy + wz * fz) / max(speed, 1e-9)
        if speed > walking_speed:
            if along > 0:
                value += walking_evidence
            elif along < 0:
                value -= walking_evidence
            elif math.isnan(along):
                value = np.nan
        evidence[u] = value if math.isfinite(value) else 0.0
    return evidence


@njit(cache=True, error_model="numpy")
def label_rows(  # noqa: PLR0917
    markers: np.ndarray,
    present: np.ndarray,
    links: np.ndarray,
    link_present: np.ndarray,
    flips: np.ndarray,
    part: np.ndarray,
    mirror: np.ndarray,
    track_velocities: np.ndarray,
) -> None:
    """One output detection, in place: parts in ``flips`` relabelled, velocities filled.

    Link ids are child joint ids, so links take the joints' order. A present joint without a
    finite velocity takes its track's.
    """
    n_joints = len(part)
    if flips.any():
        order = np.empty(n_joints, dtype=np.int64)
        _order(flips, part, mirror, order)
        moved_markers = markers[order].copy()
        moved_present = present[order].copy()
        moved_links = links[order].copy()
        moved_link_present = link_present[order].copy()
        markers[:] = moved_markers
        present[:] = moved_present
        links[:] = moved_links
        link_present[:] = moved_link_present
    for j in range(n_joints):
        if present[j] and not (
            math.isfinite(markers[j, 8]) and math.isfinite(markers[j, 9])
            and math.isfinite(markers[j, 10])
        ):  # fmt: skip
            markers[j, 8] = track_velocities[j, 0]
            markers[j, 9] = track_velocities[j, 1]
            markers[j, 10] = track_velocities[j, 2]


@njit(cache=True, error_model="numpy")
def move_rows(
    rows: np.ndarray, rotation: np.ndarray, translation: np.ndarray, quaternion: np.ndarray
) -> None:
    """Marker/link rows ``(N, 20)`` moved in place by a rigid transform.

    ``R p + t`` on the position, ``quaternion`` ``(4, 4)`` (the product ``q_R ⊗ q``) on the
    orientation normalised first, ``R`` on each twist and acceleration vector; a field with
    any NaN becomes (stays) all NaN, a zero quaternion becomes NaN.
    """
    vector = np.empty(4)
    for i in range(len(rows)):
        _rotate(rows, i, 1, rotation, translation)
        for start in (8, 11, 14, 17):
            _rotate(rows, i, start, rotation, _ZERO3)
        _turn_quaternion(rows, i, 4, quaternion, vector)


@njit(cache=True, error_model="numpy")
def move_boxes(
    boxes: np.ndarray, rotation: np.ndarray, translation: np.ndarray, quaternion: np.ndarray
) -> None:
    """Bounding boxes ``(N, 22)`` moved in place: centre position (0:3), orientation (3:7)."""
    vector = np.empty(4)
    for i in range(len(boxes)):
        _rotate(boxes, i, 0, rotation, translation)
        _turn_quaternion(boxes, i, 3, quaternion, vector)


_ZERO3 = np.zeros(3)


@njit(cache=True, error_model="numpy")
def _turn_quaternion(
    rows: np.ndarray, i: int, start: int, quaternion: np.ndarray, vector: np.ndarray
) -> None:
    """``rows[i, start:start + 4]`` normalised, then multiplied by ``quaternion`` (4, 4).

    ``vector`` (4,) is scratch space, so that the per-row loop allocates nothing.
    """
    norm = math.sqrt(
        rows[i, start] * rows[i, start]
        + rows[i, start + 1] * rows[i, start + 1]
        + rows[i, start + 2] * rows[i, start + 2]
        + rows[i, start + 3] * rows[i, start + 3]
    )
    for k in range(4):
        vector[k] = rows[i, start + k] / norm
    for k in range(4):
        rows[i, start + k] = (
            quaternion[k, 0] * vector[0]
            + quaternion[k, 1] * vector[1]
            + quaternion[k, 2] * vector[2]
            + quaternion[k, 3] * vector[3]
        )


@njit(cache=True, error_model="numpy")
def _rotate(
    rows: np.ndarray, i: int, start: int, rotation: np.ndarray, translation: np.ndarray
) -> None:
    """``rows[i, start:start + 3]`` replaced by ``R v + t``."""
    x, y, z = rows[i, start], rows[i, start + 1], rows[i, start + 2]
    for k in range(3):
        rows[i, start + k] = (
            rotation[k, 0] * x + rotation[k, 1] * y + rotation[k, 2] * z + translation[k]
        )
