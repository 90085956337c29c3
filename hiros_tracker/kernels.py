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
    "INFEASIBLE",
    "canonical_poses",
    "fold_hits",
    "frame_costs",
    "frame_pairs",
    "gate_costs",
    "hit_frame",
    "label_frame",
    "label_rows",
    "live_tracks",
    "masked_positions",
    "match_costs",
    "move_frame",
    "moved_frame",
    "relabel",
    "turn_facing",
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
    sides: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """Matched detections in their tracks' labelling, hips/eyes/ears put on the shoulders' side.

    ``positions`` ``(D, J, 3)`` are the frame's detections, ``rows`` ``(U,)`` those matched
    and ``flips`` ``(U, K)`` the parts to relabel in each (``part``, ``mirror`` as in
    ``match_costs``; the input is not changed). With ``align``, parts whose left/right pair
    (``pairs`` ``(P, 2)``, of parts ``pair_parts`` ``(P,)``) points against the
    ``shoulders`` ``(2,)`` (cos < -0.5) are flipped too; nothing is flagged where a joint is
    missing, or without shoulders (empty).

    With ``align``, the whole body's sides are then held to the track's (``_reversed_sides``):
    ``sides`` are the tracks' poses ``(T, J, 3)``, the ``(U,)`` track rows of the detections,
    and the left and right shoulder and hip ``(2,)`` each (empty: not held).

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
    tracks, track_rows, left, right = sides
    for u in range(n_pairs if align and len(left) else 0):
        if _reversed_sides(canonical[u], tracks[track_rows[u]], left, right):
            for k in range(flips.shape[1]):
                flips[u, k] = not flips[u, k]
            _order(flips[u], part, mirror, order)
            for j in range(n_joints):
                canonical[u, j] = positions[rows[u], order[j]]
    return canonical, flips


REVERSED_COS = 0.5
"""A detection's left-right axis against its track's beyond this (cos < -it) is reversed."""


@njit(cache=True, error_model="numpy")
def _reversed_sides(
    detection: np.ndarray, track: np.ndarray, left: np.ndarray, right: np.ndarray
) -> bool:
    """Whether a detection's left points to its track's right (its sides then all swapped).

    The left-right axis is the left shoulder and hip less the right ones: they lie in the
    body's frontal plane, so a front/back flip (a reflection through that plane) leaves them
    where they were and only exchanges their labels, whereas hands, feet and the head swing
    out of it; relabelling part by part on every joint can then keep a flipped detection's
    labels and drag its track into the mirrored labelling. Reversed is a cosine under -0.5;
    nothing is said where a joint is missing.
    """
    dx = dy = dz = tx = ty = tz = 0.0
    for i in range(len(left)):
        dx += detection[left[i], 0] - detection[right[i], 0]
        dy += detection[left[i], 1] - detection[right[i], 1]
        dz += detection[left[i], 2] - detection[right[i], 2]
        tx += track[left[i], 0] - track[right[i], 0]
        ty += track[left[i], 1] - track[right[i], 1]
        tz += track[left[i], 2] - track[right[i], 2]
    along = dx * tx + dy * ty + dz * tz
    scale = math.sqrt((dx * dx + dy * dy + dz * dz) * (tx * tx + ty * ty + tz * tz))
    return along < -REVERSED_COS * scale


@njit(cache=True, error_model="numpy")
def frame_costs(  # noqa: PLR0917 - match_costs' and gate_costs' arguments
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
    last_hit_ns: np.ndarray,
    confirmed: np.ndarray,
    body_ids: np.ndarray,
    seen: np.ndarray,
    det_ids: np.ndarray,
    camera: int,
    gate_stamp_ns: int,
    recent_ns: int,
    bonus: float,
    gate_distance: float,
    gate_growth: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``match_costs`` then ``gate_costs`` in one call (each takes its own arguments, in order).

    Returns:
        ``(T, D)`` costs, ``(T, D, K)`` mirrored parts, ``(T, D)`` feasible pairs and ``(T,)``
        cascade levels.

    """
    cost, flips = match_costs(positions, velocity, times_ns, stamp_ns, max_prediction,
                              detections, weights, part, mirror, n_parts, use_parts,
                              min_joints, margin)  # fmt: skip
    feasible, levels = gate_costs(cost, last_hit_ns, confirmed, body_ids, seen, det_ids,
                                  camera, gate_stamp_ns, recent_ns, bonus, gate_distance,
                                  gate_growth)  # fmt: skip
    return cost, flips, feasible, levels


@njit(cache=True, error_model="numpy")
def gate_costs(  # noqa: PLR0917
    cost: np.ndarray,
    last_hit_ns: np.ndarray,
    confirmed: np.ndarray,
    body_ids: np.ndarray,
    seen: np.ndarray,
    det_ids: np.ndarray,
    camera: int,
    stamp_ns: int,
    recent_ns: int,
    bonus: float,
    gate_distance: float,
    gate_growth: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Finish the costs ``(T, D)`` in place: body-id evidence added, gated-out pairs excluded.

    Body-id evidence (times ``bonus`` metres, when not 0): -1 where the camera keeps the body
    id it gave the track last time (``body_ids``/``seen`` ``(T, C)``), +1 for the track's other
    candidates when that id is in the frame (``det_ids`` ``(D,)``): the camera still follows
    the track's body as another detection. A pair is feasible when its cost is finite and
    within the track's gate, ``gate_distance`` widened by ``gate_growth`` per second unseen;
    the others get ``INFEASIBLE`` so that the solver still sees a full matrix.

    Returns:
        ``(T, D)`` feasible pairs and ``(T,)`` each track's level in the matching cascade:
        0 confirmed and hit since ``recent_ns``, 1 other confirmed, 2 tentative.

    """
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


@njit(cache=True, error_model="numpy")
def hit_frame(  # noqa: PLR0917 - a compiled kernel takes plain positional values
    table: tuple,
    frame: tuple,
    pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
    layout: tuple,
    camera: int,
    stamp_ns: int,
    settings: tuple[float, float, int, bool, bool, bool, bool],
    facing_args: tuple,
) -> tuple[np.ndarray, bool, np.ndarray, int, np.ndarray, bool]:
    """One frame's matched pairs folded into their tracks, in one call (``Tracker._hit``).

    In order: the detections in their tracks' labelling (``canonical_poses``), folded in
    (``fold_hits``), their orientations taken (when orientations count), the tracks' facing
    weighed (``turn_facing``), and, when every track hit is confirmed, the output detections
    labelled in place (``label_frame``); a frame with tracks to confirm or votes to count
    leaves that to the caller, which must confirm before labelling.

    ``table`` holds the ``TrackTable`` fields in ``TrackTable.hit_fields`` order (changed in
    place); ``frame`` the detections' ``(D, J, 3)`` positions, ``(D,)`` body ids, ``(D,)``
    their rows in the stacked rows that follow (markers, presence, links, link presence:
    labelled in place); ``pairs`` the
    ``frame_pairs`` rows, detections and flips; ``layout`` the mirror part and permutation,
    the joint weights, the shoulders, side pairs and their parts (``_side_arrays``) and the
    body frame (``turn_facing``); ``settings`` the smoothing, the longest prediction (s), the
    velocity window (ns) and whether to align hips to shoulders, take orientations, weigh the
    facing and label; ``facing_args`` the world's up, the camera's position and whether it is
    known, and the facing priors (``turn_facing``).

    Returns:
        ``(U, K)`` the parts relabelled in each detection (its track's swaps included), whether
        a record ring is full (``fold_hits``), ``(U,)`` which tracks turned and how many, the
        ``(U,)`` track ids and whether the detections were labelled.

    """
    (positions, orientations, velocities, velocity, time_ns, last_hit_ns, epoch_ns, hits,
     n_cameras, body_ids, seen, sums, record_ns, record_camera, record_terms, record_start,
     record_count, facing, facing_ns, flip_state, flip_ns, flip_known, confirmed,
     ids) = table  # fmt: skip
    detections, det_ids, index, markers, present, links, link_present = frame
    rows, dets, flips = pairs
    part, mirror, weights, shoulders, side_pairs, side_parts, body = layout
    smoothing, max_prediction, window_ns, align, orient, weigh, label = settings
    up, camera_position, has_camera, priors = facing_args
    canonical, flips = canonical_poses(detections, dets, flips, part, mirror, align, shoulders,
                                       side_pairs, side_parts,
                                       (positions, rows, body[2], body[3]))  # fmt: skip
    full = fold_hits(positions, velocities, velocity, time_ns, last_hit_ns, epoch_ns, hits,
                     n_cameras, body_ids, seen, sums, record_ns, record_camera, record_terms,
                     record_start, record_count, rows, canonical, det_ids[dets], camera,
                     stamp_ns, smoothing, max_prediction, window_ns, weights)  # fmt: skip
    if orient:
        _take_orientations(orientations, rows, markers, index[dets], flips, part, mirror)
    turned = np.zeros(len(rows), dtype=np.bool_)
    if weigh:
        turned = turn_facing(positions, orientations, velocities, velocity, sums, record_terms,
                             record_start, record_count, facing, facing_ns, rows, canonical,
                             up, camera_position, has_camera, body, priors, stamp_ns,
                             (camera, flip_state, flip_ns, flip_known))  # fmt: skip
    n_turned = 0
    for u in range(len(rows)):
        if turned[u]:
            flips[u, :] = ~flips[u, :]
            n_turned += 1
    every = True
    for u in range(len(rows)):
        every &= confirmed[rows[u]]
    labelled = label and every
    if labelled:
        label_frame(markers, present, links, link_present, index[dets], flips, part, mirror,
                    velocities, rows, confirmed)  # fmt: skip
    return flips, full, turned, n_turned, ids[rows], labelled


@njit(cache=True, error_model="numpy")
def _take_orientations(  # noqa: PLR0917
    orientations: np.ndarray,
    rows: np.ndarray,
    markers: np.ndarray,
    dets: np.ndarray,
    flips: np.ndarray,
    part: np.ndarray,
    mirror: np.ndarray,
) -> None:
    """Track ``rows[u]`` takes the orientations of the detection in row ``dets[u]``.

    Relabelled by ``flips[u]``, when it has any (``markers`` ``(D, J, 20)``, orientation in
    columns 4:8): the orientation cost compares a detection with its track's last ones.
    """
    order = np.empty(len(part), dtype=np.int64)
    for u in range(len(rows)):
        d = dets[u]
        known = False
        for j in range(len(part)):
            for a in range(4):
                known |= math.isfinite(markers[d, j, 4 + a])
        if known:
            _order(flips[u], part, mirror, order)
            for j in range(len(part)):
                for a in range(4):
                    orientations[rows[u], j, a] = markers[d, order[j], 4 + a]


@njit(cache=True, error_model="numpy")
def live_tracks(  # noqa: PLR0917
    last_hit_ns: np.ndarray,
    confirmed: np.ndarray,
    n_tracks: int,
    now_ns: int,
    track_timeout: float,
    tentative_timeout: float,
) -> tuple[int, np.ndarray]:
    """How many of the first ``n_tracks`` tracks were hit within their timeout, and which."""
    keep = np.empty(n_tracks, dtype=np.bool_)
    count = 0
    for t in range(n_tracks):
        timeout = track_timeout if confirmed[t] else tentative_timeout
        keep[t] = (now_ns - last_hit_ns[t]) * 1e-9 <= timeout
        count += keep[t]
    return count, keep


@njit(cache=True, error_model="numpy")
def fold_hits(  # noqa: PLR0917 - the TrackTable's fields and one frame's hits
    positions: np.ndarray,
    velocities: np.ndarray,
    velocity: np.ndarray,
    time_ns: np.ndarray,
    last_hit_ns: np.ndarray,
    epoch_ns: np.ndarray,
    hits: np.ndarray,
    n_cameras: np.ndarray,
    body_ids: np.ndarray,
    seen: np.ndarray,
    sums: np.ndarray,
    record_ns: np.ndarray,
    record_camera: np.ndarray,
    record_terms: np.ndarray,
    record_start: np.ndarray,
    record_count: np.ndarray,
    rows: np.ndarray,
    canonical: np.ndarray,
    det_ids: np.ndarray,
    camera: int,
    stamp_ns: int,
    smoothing: float,
    max_prediction: float,
    window_ns: int,
    weights: np.ndarray,
) -> bool:
    """Fold one frame's detections into their tracks (``TrackTable`` fields, in place).

    Track ``rows[u]`` (distinct) takes ``canonical[u]`` ``(J, 3)`` (its detection in its
    labelling, NaN where unmeasured) and the camera's body id ``det_ids[u]``: its pose is
    predicted and smoothed (``_hit_one``), the detection enters its velocity window (older
    ones leave; every ``REBASE_NS`` the time origin moves, see ``_rebase``) and its velocities
    are refitted over the cameras of all the frame's tracks (``_solve_one``).

    Returns:
        whether some track's record ring is now full (the caller grows it before the next frame).

    """
    slots = record_ns.shape[1]
    for u in range(len(rows)):
        r = rows[u]
        slot = (record_start[r] + record_count[r]) % slots
        alpha = smoothing if hits[r] else 1.0
        _hit_one(positions[r], velocity[r], time_ns[r], epoch_ns[r], alpha, canonical[u],
                 stamp_ns, max_prediction, record_terms[r, slot])  # fmt: skip
        time_ns[r] = max(time_ns[r], stamp_ns)
        last_hit_ns[r] = max(last_hit_ns[r], stamp_ns)
        hits[r] += 1
        body_ids[r, camera] = det_ids[u]
        seen[r, camera] = True
        n_cameras[r] = max(n_cameras[r], camera + 1)
        record_ns[r, slot] = stamp_ns
        record_camera[r, slot] = camera
        record_count[r] += 1
        sums[r, camera] += record_terms[r, slot]
        while record_count[r] and record_ns[r, record_start[r]] < stamp_ns - window_ns:
            old = record_start[r]
            sums[r, record_camera[r, old]] -= record_terms[r, old]
            record_start[r] = (old + 1) % slots
            record_count[r] -= 1
        if stamp_ns - epoch_ns[r] > REBASE_NS:
            _rebase(r, stamp_ns, epoch_ns, sums, record_ns, record_camera, record_terms,
                    record_start, record_count)  # fmt: skip
    n_fit = 1
    for u in range(len(rows)):
        n_fit = max(n_fit, n_cameras[rows[u]])
    fitted = np.zeros(velocities.shape[1:])
    body = np.zeros(3)
    full = False
    for u in range(len(rows)):
        r = rows[u]
        if _solve_one(sums[r], n_fit, weights, fitted, body):
            velocities[r] = fitted
            velocity[r] = body
        full |= record_count[r] == slots
    return full


REBASE_NS = 30_000_000_000
"""How often (ns) a track's running sums are rebuilt around a new time origin (precision)."""


@njit(cache=True, error_model="numpy")
def _hit_one(  # noqa: PLR0917
    position: np.ndarray,
    velocity: np.ndarray,
    time_ns: int,
    epoch_ns: int,
    alpha: float,
    canonical: np.ndarray,
    stamp_ns: int,
    max_prediction: float,
    terms: np.ndarray,
) -> None:
    """A track's pose ``(J, 3)`` updated in place; its detection's fit terms into ``terms``.

    The track is predicted to ``max(time_ns, stamp_ns)``; a measured joint moves by ``alpha``
    towards the detection, an unmeasured one keeps the prediction (or takes the detection
    where the prediction is not finite). ``terms`` ``(J, 9)``: n, t, t², p (3), t·p (3) of
    the least-squares slope, ``t`` in seconds from ``epoch_ns``, zero for unmeasured joints.
    """
    now = max(time_ns, stamp_ns)
    dt = (now - time_ns) * 1e-9
    dt = min(max(dt, -max_prediction), max_prediction)
    t = (stamp_ns - epoch_ns) * 1e-9
    for j in range(len(position)):
        measured = (
            math.isfinite(canonical[j, 0])
            and math.isfinite(canonical[j, 1])
            and math.isfinite(canonical[j, 2])
        )
        for a in range(3):
            predicted = position[j, a] + velocity[a] * dt
            value = predicted
            if measured:
                value = predicted + alpha * (canonical[j, a] - predicted)
            if not math.isfinite(value):
                value = canonical[j, a]
            position[j, a] = value
        terms[j, :] = 0.0
        if measured:
            terms[j, 0] = 1.0
            terms[j, 1] = t
            terms[j, 2] = t * t
            for a in range(3):
                terms[j, 3 + a] = canonical[j, a]
                terms[j, 6 + a] = canonical[j, a] * t


@njit(cache=True, error_model="numpy")
def _rebase(  # noqa: PLR0917
    r: int,
    stamp_ns: int,
    epoch_ns: np.ndarray,
    sums: np.ndarray,
    record_ns: np.ndarray,
    record_camera: np.ndarray,
    record_terms: np.ndarray,
    record_start: np.ndarray,
    record_count: np.ndarray,
) -> None:
    """Move track ``r``'s time origin to ``stamp_ns`` and rebuild its sums, so ``t²`` stays small.

    A record's terms keep n and p; t, t² and t·p are recomputed for the new origin.
    """
    slots = record_ns.shape[1]
    epoch_ns[r] = stamp_ns
    sums[r] = 0.0
    for i in range(record_count[r]):
        slot = (record_start[r] + i) % slots
        t = (record_ns[r, slot] - stamp_ns) * 1e-9
        terms = record_terms[r, slot]
        for j in range(len(terms)):
            if terms[j, 0]:
                terms[j, 1] = t
                terms[j, 2] = t * t
                for a in range(3):
                    terms[j, 6 + a] = terms[j, 3 + a] * t
        sums[r, record_camera[r, slot]] += terms


@njit(cache=True, error_model="numpy")
def _solve_one(
    sums: np.ndarray, n_cameras: int, weights: np.ndarray, velocities: np.ndarray, body: np.ndarray
) -> bool:
    """Slopes from one track's per-camera sums ``(C, J, 9)``: one intercept per camera.

    Fits over the first ``n_cameras`` cameras; writes ``(J, 3)`` joint velocities (0 where
    undetermined) and the ``(3,)`` body velocity pooled with ``weights`` ``(J,)``; returns
    whether anything was determined.
    """
    determined = False
    pooled = 0.0
    moment = np.zeros(3)
    sxy = np.empty(3)
    for j in range(len(weights)):
        sxx = 0.0
        sxy[:] = 0.0
        for c in range(n_cameras):
            n = max(sums[c, j, 0], 1.0)
            sxx += sums[c, j, 2] - sums[c, j, 1] ** 2 / n
            for a in range(3):
                sxy[a] += sums[c, j, 6 + a] - sums[c, j, 1] * sums[c, j, 3 + a] / n
        velocities[j, :] = 0.0
        if sxx > 1e-5:
            determined = True
            pooled += sxx * weights[j]
            for a in range(3):
                velocities[j, a] = sxy[a] / sxx
                moment[a] += sxy[a] * weights[j]
    for a in range(3):
        body[a] = moment[a] / max(pooled, 1e-12)
    return determined


@njit(cache=True, error_model="numpy")
def relabel(  # noqa: PLR0917
    r: int,
    permutation: np.ndarray,
    positions: np.ndarray,
    orientations: np.ndarray,
    velocities: np.ndarray,
    sums: np.ndarray,
    record_terms: np.ndarray,
    record_start: np.ndarray,
    record_count: np.ndarray,
) -> None:
    """Reorder track ``r``'s joints (swap the sides of some parts) in every per-joint field."""
    positions[r] = positions[r][permutation]
    orientations[r] = orientations[r][permutation]
    velocities[r] = velocities[r][permutation]
    for c in range(sums.shape[1]):
        sums[r, c] = sums[r, c][permutation]
    slots = record_terms.shape[1]
    for i in range(record_count[r]):
        slot = (record_start[r] + i) % slots
        record_terms[r, slot] = record_terms[r, slot][permutation]


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
def _trunk_mean(
    positions: np.ndarray, rows: np.ndarray, root: int, neck: int
) -> tuple[np.ndarray, int]:
    """``(3,)`` mean unit root -> neck over tracks ``rows`` where it is finite, and how many."""
    mean = np.zeros(3)
    count = 0
    for r in rows:
        x, y, z = _unit3(
            positions[r, neck, 0] - positions[r, root, 0],
            positions[r, neck, 1] - positions[r, root, 1],
            positions[r, neck, 2] - positions[r, root, 2],
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
def _facing_evidence(  # noqa: PLR0917
    positions: np.ndarray,
    rows: np.ndarray,
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
    episodes: tuple[int, np.ndarray, np.ndarray, np.ndarray, float, float, int],
) -> np.ndarray:
    """``(U,)`` log-odds each detection gives that its track faces the way its sides say.

    ``positions`` ``(T, J, 3)`` the tracks' poses and ``velocity`` ``(T, 3)`` their body
    velocities, of which tracks ``rows`` ``(U,)`` were hit by ``canonical`` ``(U, J, 3)``;
    ``up`` ``(3,)`` the world's up, ``camera`` ``(3,)`` the camera's position (used when
    ``has_camera``); see ``turn_facing``.
    """
    n_pairs = len(rows)
    evidence = np.zeros(n_pairs)
    ux, uy, uz = up[0], up[1], up[2]
    cam, flip_state, flip_ns, flip_known, episode, noise, stamp_ns = episodes
    for u in range(n_pairs):
        r = rows[u]
        lx = ly = lz = 0.0
        for i in range(len(left)):
            lx += positions[r, left[i], 0]
            ly += positions[r, left[i], 1]
            lz += positions[r, left[i], 2]
        rx = ry = rz = 0.0
        for i in range(len(right)):
            rx += positions[r, right[i], 0]
            ry += positions[r, right[i], 1]
            rz += positions[r, right[i], 2]
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
                camera[0] - positions[r, root, 0],
                camera[1] - positions[r, root, 1],
                camera[2] - positions[r, root, 2],
                ux,
                uy,
                uz,
            )
            cx, cy, cz = _unit3(cx, cy, cz)
            cosine = fx * cx + fy * cy + fz * cz
            prior_right = flip_prior_back if cosine < -0.5 else flip_prior
            prior_wrong = flip_prior_back if -cosine < -0.5 else flip_prior
            if episode > 0.0 and math.isfinite(cosine):
                value = _episode_evidence(
                    flip_state[r, cam], flipped, prior_right, prior_wrong, episode, noise,
                    (stamp_ns - flip_ns[r, cam]) * 1e-9 if flip_known[r, cam] else -1.0,
                )  # fmt: skip
                flip_ns[r, cam], flip_known[r, cam] = stamp_ns, True
            else:
                value = _independent_evidence(flipped, prior_right, prior_wrong)
        else:  # no camera pose: a flipped-looking detection is simply evidence against
            value = (-1.0 if flipped else 1.0) * math.log((1.0 - flip_prior) / flip_prior)
        wx, wy, wz = _flat3(velocity[r, 0], velocity[r, 1], velocity[r, 2], ux, uy, uz)
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
def _independent_evidence(flipped: bool, prior_right: float, prior_wrong: float) -> float:
    """Log-odds of one detection taken on its own (each hypothesis' view prior)."""
    likely_right = prior_right if flipped else 1.0 - prior_right
    likely_wrong = 1.0 - prior_wrong if flipped else prior_wrong
    return math.log(likely_right / likely_wrong)


@njit(cache=True, error_model="numpy")
def _episode_evidence(  # noqa: PLR0917
    state: np.ndarray,
    flipped: bool,
    prior_right: float,
    prior_wrong: float,
    episode: float,
    noise: float,
    elapsed: float,
) -> float:
    """Log-odds one detection adds for its track's facing, knowing SDK flips last seconds.

    An SDK flips a body front/back for seconds at a time, so one camera's consecutive flipped
    detections are one event, not independent votes. For each hypothesis (the track's sides
    right, or reversed) a two-state filter follows whether this camera's SDK is in a flip
    episode: episodes last ``episode`` s on average and cover the share of time the view's
    flip prior says; an observation is misread with probability ``noise``. The detection adds
    the log ratio of the two hypotheses' predictive likelihoods; a run of flipped detections
    then costs about one flip prior, plus little per frame, instead of a prior per frame.

    ``state`` ``(2,)``: P(SDK flipped) under "right" and "reversed", updated in place;
    ``elapsed`` s since this camera's previous detection of the track (< 0: the first).
    """
    priors = (prior_right, prior_wrong)
    likely = np.empty(2)
    for h in range(2):
        if elapsed < 0.0:
            before = priors[h]
        else:  # relax towards the view's prior: leave rate 1/episode, share = prior
            keep = math.exp(-elapsed / (episode * (1.0 - priors[h])))
            before = state[h] * keep + priors[h] * (1.0 - keep)
        # under "right" a flipped observation means the SDK flipped; under "reversed", not
        sdk_flip_seen = flipped if h == 0 else not flipped
        if sdk_flip_seen:
            with_flip, without_flip = before * (1.0 - noise), (1.0 - before) * noise
        else:
            with_flip, without_flip = before * noise, (1.0 - before) * (1.0 - noise)
        likely[h] = with_flip + without_flip
        state[h] = with_flip / likely[h]
    return math.log(likely[0] / likely[1])


@njit(cache=True, error_model="numpy")
def turn_facing(  # noqa: PLR0917 - the TrackTable's fields and one frame's evidence
    positions: np.ndarray,
    orientations: np.ndarray,
    velocities: np.ndarray,
    velocity: np.ndarray,
    sums: np.ndarray,
    record_terms: np.ndarray,
    record_start: np.ndarray,
    record_count: np.ndarray,
    facing: np.ndarray,
    facing_ns: np.ndarray,
    rows: np.ndarray,
    canonical: np.ndarray,
    up: np.ndarray,
    camera: np.ndarray,
    has_camera: bool,
    body: tuple[int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    priors: tuple[float, float, float, float, float, float, float, float],
    stamp_ns: int,
    episodes: tuple[int, np.ndarray, np.ndarray, np.ndarray],
) -> np.ndarray:
    """Weigh one frame's evidence on each hit track's facing; relabel tracks found reversed.

    For a detection (in its track's labelling) with anatomical forward ``a`` and a track
    front ``f``: if the track is right, the detection is flipped iff ``a·f < 0``; if the
    track is mirrored, the opposite, and its front is ``-f``. Each hypothesis' likelihood
    uses the flip prior for the view the camera would have (back: cos(f, to camera) < -0.5);
    walking forward adds evidence (``_facing_evidence``). Evidence fades over the facing
    memory; a track whose log-odds fall below minus the threshold is relabelled (all parts).

    ``positions`` to ``facing_ns`` are the ``TrackTable``'s fields (changed in place;
    ``facing`` ``(T,)`` is each track's log-odds that its sides are right, set at
    ``facing_ns``); ``rows`` ``(U,)`` are the tracks hit by ``canonical`` ``(U, J, 3)``;
    ``up`` ``(4,)`` is the world's up (``_update_up``, changed in place); ``camera`` ``(3,)``
    the camera's position, used when ``has_camera``; ``body`` the root, neck, left ``(2,)``,
    right ``(2,)``, forward pointers ``(k, 2)`` (``_BodyFrame``) and the mirror permutation
    ``(J,)``; ``priors`` the flip prior, the flip prior seen from the back, walking speed,
    walking evidence, facing memory (s), facing threshold, mean flip episode (s; 0 treats
    detections as independent) and the chance a detection's facing is misread;
    ``episodes`` the camera's code and the ``TrackTable``'s ``flip_state`` ``(T, C, 2)``,
    ``flip_ns`` ``(T, C)`` and ``flip_known`` ``(T, C)`` (see ``_episode_evidence``).

    Returns:
        ``(U,)`` which tracks were relabelled.

    """
    root, neck, left, right, pointers, mirror = body
    flip_prior, flip_prior_back, walking_speed, walking_evidence = priors[:4]
    memory, threshold, episode, noise = priors[4:]
    cam, flip_state, flip_ns, flip_known = episodes
    world_up = _update_up(up, positions, rows, root, neck)
    evidence = _facing_evidence(
        positions, rows, canonical, velocity, world_up, camera, has_camera, root, left, right,
        pointers, flip_prior, flip_prior_back, walking_speed, walking_evidence,
        (cam, flip_state, flip_ns, flip_known, episode, noise, stamp_ns),
    )  # fmt: skip
    turned = np.zeros(len(rows), dtype=np.bool_)
    for u in range(len(rows)):
        r = rows[u]
        fade = math.exp(-max(stamp_ns - facing_ns[r], 0) * 1e-9 / memory)
        facing[r] = facing[r] * fade + evidence[u]
        facing_ns[r] = stamp_ns
        if facing[r] < -threshold:
            relabel(r, mirror, positions, orientations, velocities, sums, record_terms,
                    record_start, record_count)  # fmt: skip
            facing[r] = -facing[r]
            for c in range(flip_state.shape[1]):  # the hypotheses trade places
                flip_state[r, c, 0], flip_state[r, c, 1] = flip_state[r, c, 1], flip_state[r, c, 0]
            turned[u] = True
    return turned


@njit(cache=True, error_model="numpy")
def _update_up(
    up: np.ndarray, positions: np.ndarray, rows: np.ndarray, root: int, neck: int
) -> np.ndarray:
    """``(3,)`` the world's up: a running mean of the hit tracks' trunks (root -> neck).

    ``up`` ``(4,)`` is the state: x, y, z and whether it is known (0 before the first trunk;
    NaN is returned then). The world frame may be a camera's (y down) or z-up; people stand
    most of the time, and one bending person must not tilt the front the facing compares with.
    """
    mean, count = _trunk_mean(positions, rows, root, neck)
    if count:
        for a in range(3):
            up[a] = mean[a] if up[3] == 0.0 else up[a] + 0.01 * (mean[a] - up[a])
        norm = math.sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2])
        for a in range(3):
            up[a] = up[a] / norm
        up[3] = 1.0
    if up[3] == 0.0:
        return np.full(3, np.nan)
    return up[:3].copy()


@njit(cache=True, error_model="numpy")
def label_frame(  # noqa: PLR0917
    markers: np.ndarray,
    present: np.ndarray,
    links: np.ndarray,
    link_present: np.ndarray,
    index: np.ndarray,
    flips: np.ndarray,
    part: np.ndarray,
    mirror: np.ndarray,
    velocities: np.ndarray,
    rows: np.ndarray,
    confirmed: np.ndarray,
) -> None:
    """``label_rows`` on a stacked frame: each pair ``u`` whose track ``rows[u]`` is confirmed.

    ``markers`` ``(D, J, 20)``, ``present`` ``(D, J)`` and the links alike are the frame's
    detections; pair ``u`` is detection ``index[u]`` with flips ``flips[u]`` and its track's
    ``velocities[rows[u]]`` (``(T, J, 3)``, ``confirmed`` ``(T,)``: the track table's).
    """
    for u in range(len(rows)):
        if confirmed[rows[u]]:
            d = index[u]
            label_rows(markers[d], present[d], links[d], link_present[d], flips[u], part,
                       mirror, velocities[rows[u]])  # fmt: skip


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
def move_frame(  # noqa: PLR0917
    markers: np.ndarray,
    links: np.ndarray,
    boxes: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    quaternion: np.ndarray,
) -> None:
    """A frame's marker and link rows ``(D, N, 20)`` and boxes ``(D, 22)`` moved in place.

    One call for the whole frame (see ``move_rows`` and ``move_boxes``).
    """
    for d in range(len(markers)):
        move_rows(markers[d], rotation, translation, quaternion)
    for d in range(len(links)):
        move_rows(links[d], rotation, translation, quaternion)
    move_boxes(boxes, rotation, translation, quaternion)


@njit(cache=True, error_model="numpy")
def moved_frame(  # noqa: PLR0917
    markers: np.ndarray,
    present: np.ndarray,
    links: np.ndarray,
    link_present: np.ndarray,
    boxes: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    quaternion: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``move_frame`` on copies of a frame's ``SkeletonRows`` fields, in their order.

    The input stays as it is. One call copies all five (a numpy ``copy`` each cost about as
    much as the move itself).
    """
    out = (markers.copy(), present.copy(), links.copy(), link_present.copy(), boxes.copy())
    move_frame(out[0], out[2], out[4], rotation, translation, quaternion)
    return out


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
