"""Association costs: how far each detection is from each track, and which pairs may match.

One frame's whole cost matrix in one compiled call (``frame_costs``): each track predicted to
the frame's stamp, compared with every detection joint by joint, each mirror part also
compared mirrored, body-id evidence added and pairs beyond the track's gate excluded; then
the solver's pairs turned into each detection's track (``frame_pairs``). Shapes as in
``tracker.py``; the maths of each kernel is in its docstring, and
``test/hiros_tracker/test_kernel_reference.py`` restates it in numpy and holds the kernels to it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hiros_tracker.kernel_args import (
    GateFrame,
    GateSettings,
    GateTracks,
    MatchSettings,
    MirrorLayout,
    TrackPoses,
)

__all__ = [
    "INFEASIBLE",
    "frame_costs",
    "frame_pairs",
    "gate_costs",
    "masked_positions",
    "match_costs",
]


INFEASIBLE = 1e9
"""Cost given to gated-out pairs so that the assignment solver still sees a full matrix."""


@njit(cache=True, error_model="numpy")
def masked_positions(
    markers: np.ndarray, present: np.ndarray, min_confidence: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``(D, J, 3)`` positions, NaN where absent or below ``min_confidence``; ``(D,)`` usable.

    A detection is usable when one of its present joints has a finite position (whatever
    its confidence). Also returns ``(D,)`` how many joints each keeps (finite positions) and
    how many detections are not usable.
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
    return positions, usable, kept, n_det - int(usable.sum())


@njit(cache=True, error_model="numpy")
def match_costs(  # noqa: PLR0912, PLR0915, PLR0917 - one loop nest, one frame's input
    tracks: TrackPoses,
    detections: np.ndarray,
    stamp_ns: int,
    weights: np.ndarray,
    layout: MirrorLayout,
    settings: MatchSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """Each track predicted to ``stamp_ns``, then the cost of every (track, detection).

    Track ``t`` (``tracks``: pose ``P_t`` ``(J, 3)`` at ``time_ns[t]``, body velocity ``v_t``)
    is predicted to ``Q_t = P_t + v_t * clip(stamp - time_ns[t], ±max_prediction)`` (s), and
    compared with detection ``X_d`` ``(D, J, 3)`` (NaN for joints left out) joint by joint:
    ``e_j = |Q_tj - X_dj|`` as given, ``m_j = |Q_tj - X_d,mirror[j]|`` mirrored. With
    ``use_parts``, part ``k`` (``layout.part == k``; -1 on the midline) is taken mirrored
    when it has a finite ``m_j`` and ``mean_k(m) + margin < mean_k(e)`` (plain means over the
    part's finite distances; an empty as-given mean is 0). The cost is the ``weights`` ``w``
    mean ``sum_j w_j c_j / sum_j w_j`` over the joints where the chosen distance ``c_j`` is
    finite: ``inf`` below ``min_joints`` such joints, NaN when their weights sum to 0.

    Returns:
        ``(T, D)`` costs (m) and ``(T, D, K)`` the parts taken mirrored.

    """
    positions, velocity, times_ns = tracks.positions, tracks.velocity, tracks.time_ns
    part, mirror, n_parts = layout.part, layout.mirror, layout.n_parts
    max_prediction, use_parts = settings.max_prediction, settings.use_parts
    min_joints, margin = settings.min_joints, settings.margin
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
def frame_costs(  # noqa: PLR0917 - match_costs' and gate_costs' arguments
    tracks: TrackPoses,
    detections: np.ndarray,
    weights: np.ndarray,
    layout: MirrorLayout,
    match: MatchSettings,
    gate_tracks: GateTracks,
    frame: GateFrame,
    gate: GateSettings,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``match_costs`` at ``frame.stamp_ns``, then ``gate_costs``, in one call.

    Returns:
        ``(T, D)`` costs, ``(T, D, K)`` mirrored parts, ``(T, D)`` feasible pairs and ``(T,)``
        cascade levels.

    """
    cost, flips = match_costs(tracks, detections, frame.stamp_ns, weights, layout, match)
    feasible, levels = gate_costs(cost, gate_tracks, frame, gate)
    return cost, flips, feasible, levels


@njit(cache=True, error_model="numpy")
def gate_costs(
    cost: np.ndarray, tracks: GateTracks, frame: GateFrame, settings: GateSettings
) -> tuple[np.ndarray, np.ndarray]:
    """Finish the costs ``(T, D)`` in place: body-id evidence added, gated-out pairs excluded.

    Body-id evidence, when ``bonus`` is not 0: with ``b`` the body id camera ``frame.camera``
    gave track ``t`` last time (``body_ids``/``seen`` ``(T, C)``; none if unseen), the cost
    of detection ``d`` (body id ``det_ids[d]``) gains ``-bonus`` when ``det_ids[d] == b >= 0``
    (the camera keeps following the track's body), else ``+bonus`` when some detection of the
    frame has id ``b`` (the camera follows the track's body as another detection), else 0.
    A pair is feasible when its cost is finite and ``<= distance + growth * max(stamp -
    last_hit_ns[t], 0)`` (s): the gate widens while a track is unseen. The others get
    ``INFEASIBLE``, so that the solver still sees a full matrix.

    Returns:
        ``(T, D)`` feasible pairs and ``(T,)`` each track's level in the matching cascade:
        0 confirmed and hit since ``recent_ns``, 1 other confirmed, 2 tentative.

    """
    last_hit_ns, confirmed = tracks.last_hit_ns, tracks.confirmed
    body_ids, seen = tracks.body_ids, tracks.seen
    det_ids, camera, stamp_ns, recent_ns = (
        frame.det_ids,
        frame.camera,
        frame.stamp_ns,
        frame.recent_ns,
    )
    bonus, gate_distance, gate_growth = settings.bonus, settings.distance, settings.growth
    n_tracks, n_det = cost.shape
    feasible = np.zeros((n_tracks, n_det), dtype=np.bool_)
    levels = np.empty(n_tracks, dtype=np.int64)
    for t in range(n_tracks):
        known = body_ids[t, camera] if seen[t, camera] else -1
        elsewhere = 0.0
        for d in range(n_det):
            if known >= 0 and det_ids[d] == known:
                elsewhere = 1.0
        gate = gate_distance + gate_growth * max((stamp_ns - last_hit_ns[t]) * 1e-9, 0.0)
        for d in range(n_det):
            if bonus:
                term = -1.0 if known == det_ids[d] and det_ids[d] >= 0 else elsewhere
                cost[t, d] += bonus * term
            feasible[t, d] = math.isfinite(cost[t, d]) and cost[t, d] <= gate
            if not feasible[t, d]:
                cost[t, d] = INFEASIBLE
        levels[t] = (0 if last_hit_ns[t] >= recent_ns else 1) if confirmed[t] else 2
    return feasible, levels


@njit(cache=True, error_model="numpy")
def frame_pairs(  # noqa: PLR0917
    r: np.ndarray,
    c: np.ndarray,
    feasible: np.ndarray,
    flips: np.ndarray,
    kept: np.ndarray,
    min_joints: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """Each detection's track from the solver's pairs: its match, else a new track, else none.

    The solver paired tracks ``r`` with detections ``c`` (``(N,)`` each); a pair counts when
    ``feasible`` ``(T, D)``. A detection left unmatched starts a track when it keeps
    ``min_joints`` joints (``kept`` ``(D,)``), else it is dropped.

    Returns:
        ``(U,)`` track rows (-1: a new track, which the caller makes), ``(U,)`` their
        detections in detection order, ``(U, K)`` the parts to relabel in each (the pair's
        ``flips`` ``(T, D, K)``, none for a new track), how many new tracks and how many
        detections were dropped.

    """
    n_det = len(kept)
    matched = np.full(n_det, -1, dtype=np.int64)
    for i in range(len(r)):
        if feasible[r[i], c[i]]:
            matched[c[i]] = r[i]
    count = 0
    for d in range(n_det):
        count += matched[d] >= 0 or kept[d] >= min_joints
    rows = np.empty(count, dtype=np.int64)
    dets = np.empty(count, dtype=np.int64)
    pair_flips = np.zeros((count, flips.shape[2]), dtype=np.bool_)
    u = 0
    new = 0
    for d in range(n_det):
        if matched[d] >= 0:
            pair_flips[u] = flips[matched[d], d]
        elif kept[d] >= min_joints:
            new += 1
        else:
            continue
        rows[u] = matched[d]
        dets[u] = d
        u += 1
    return rows, dets, pair_flips, new, n_det - count
