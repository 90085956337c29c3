"""The tracker's association kernels stated in numpy (part of ``tracker_reference``).

The costs of pairing tracks with detections and the pairs chosen: ``masked_positions``,
``match_costs``, ``gate_costs``, ``frame_costs`` and ``frame_pairs`` of
``hiros_tracker.association``, written from the kernels' docstrings. ``tracker_reference``
re-exports them beside the other kernels' references.
"""

from __future__ import annotations

import numpy as np

from hiros_tracker.kernel_args import (
    GateFrame,
    GateSettings,
    GateTracks,
    MatchSettings,
    MirrorLayout,
    TrackPoses,
)

INFEASIBLE = 1e9
"""The cost of a gated-out pair (``association.INFEASIBLE``)."""


def vector_norm(vectors: np.ndarray) -> np.ndarray:
    """Euclidean length along the last axis."""
    return np.sqrt(np.sum(vectors * vectors, axis=-1))


# ------------------------------------------------------------------------------ association
def reference_masked_positions(
    markers: np.ndarray, present: np.ndarray, min_confidence: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``masked_positions``: positions kept where present and confident enough.

    ``markers`` ``(D, J, 20)``: confidence in column 0, position in 1:4. A joint is kept when
    present and not below ``min_confidence`` (a NaN confidence is not below; 0: no floor).
    """
    xyz = markers[..., 1:4]
    finite = np.isfinite(xyz).all(axis=-1)
    with np.errstate(invalid="ignore"):
        unconfident = (min_confidence > 0) & (markers[..., 0] < min_confidence)
    keep = present & ~unconfident
    positions = np.where(keep[..., None], xyz, np.nan)
    usable = (present & finite).any(axis=1)
    kept = (keep & finite).sum(axis=1)
    return positions, usable, kept, int((~usable).sum())


def reference_match_costs(  # noqa: PLR0917 - the kernel's inputs
    tracks: TrackPoses,
    detections: np.ndarray,
    stamp_ns: int,
    weights: np.ndarray,
    layout: MirrorLayout,
    settings: MatchSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """``match_costs``: ``(T, D)`` weighted mean joint distances, ``(T, D, K)`` parts mirrored."""
    part, mirror, n_parts = layout.part, layout.mirror, layout.n_parts
    dt = np.clip(
        (stamp_ns - tracks.time_ns) * 1e-9, -settings.max_prediction, settings.max_prediction
    )
    predicted = tracks.positions + tracks.velocity[:, None, :] * dt[:, None, None]  # (T, J, 3)
    given = vector_norm(predicted[:, None] - detections[None])  # (T, D, J)
    mirrored = vector_norm(predicted[:, None] - detections[None][:, :, mirror])
    flips = np.zeros((*given.shape[:2], n_parts), dtype=bool)
    if settings.use_parts:
        for k in range(n_parts):
            in_part = part == k
            mean_given = np.nansum(given[..., in_part], axis=2) / np.maximum(
                np.isfinite(given[..., in_part]).sum(axis=2), 1
            )
            count_mirrored = np.isfinite(mirrored[..., in_part]).sum(axis=2)
            mean_mirrored = np.nansum(mirrored[..., in_part], axis=2) / np.maximum(
                count_mirrored, 1
            )
            flips[..., k] = (count_mirrored > 0) & (mean_mirrored + settings.margin < mean_given)
    sided = part >= 0
    take_mirrored = np.zeros(given.shape, dtype=bool)
    take_mirrored[..., sided] = flips[..., part[sided]]
    chosen = np.where(take_mirrored, mirrored, given)
    finite = np.isfinite(chosen)
    norm = (finite * weights).sum(axis=2)
    total = np.where(finite, chosen * weights, 0.0).sum(axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        cost = np.where(norm > 0, total / norm, np.nan)
    cost[finite.sum(axis=2) < settings.min_joints] = np.inf
    return cost, flips


def reference_gate_costs(
    cost: np.ndarray, tracks: GateTracks, frame: GateFrame, settings: GateSettings
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``gate_costs``: the finished ``(T, D)`` costs, ``(T, D)`` feasible and ``(T,)`` levels."""
    n = len(cost)  # the table's rows past the tracks' are not read
    known = np.where(tracks.seen[:n, frame.camera], tracks.body_ids[:n, frame.camera], -1)
    same = (frame.det_ids[None, :] == known[:, None]) & (frame.det_ids[None, :] >= 0)
    elsewhere = ((known >= 0)[:, None] & (frame.det_ids[None, :] == known[:, None])).any(axis=1)
    term = np.where(same, -1.0, elsewhere[:, None].astype(float))
    if settings.bonus:
        cost = cost + settings.bonus * term
    unseen = np.maximum((frame.stamp_ns - tracks.last_hit_ns[:n]) * 1e-9, 0.0)
    gate = settings.distance + settings.growth * unseen
    with np.errstate(invalid="ignore"):
        feasible = np.isfinite(cost) & (cost <= gate[:, None])
    cost = np.where(feasible, cost, INFEASIBLE)
    recent = tracks.last_hit_ns[:n] >= frame.recent_ns
    levels = np.where(tracks.confirmed[:n], np.where(recent, 0, 1), 2)
    return cost, feasible, levels


def reference_frame_costs(  # noqa: PLR0917 - the kernel's inputs
    tracks: TrackPoses,
    detections: np.ndarray,
    weights: np.ndarray,
    layout: MirrorLayout,
    match: MatchSettings,
    gate_tracks: GateTracks,
    frame: GateFrame,
    gate: GateSettings,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``frame_costs``: the costs at the frame's stamp, gated; flips, feasible pairs, levels."""
    cost, flips = reference_match_costs(tracks, detections, frame.stamp_ns, weights, layout, match)
    cost, feasible, levels = reference_gate_costs(cost, gate_tracks, frame, gate)
    return cost, flips, feasible, levels


def reference_frame_pairs(  # noqa: PLR0917 - the kernel's inputs
    r: np.ndarray,
    c: np.ndarray,
    feasible: np.ndarray,
    flips: np.ndarray,
    kept: np.ndarray,
    min_joints: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """``frame_pairs``: each detection's track (-1: new), its detection, flips, new, dropped."""
    matched = {int(d): int(t) for t, d in zip(r, c, strict=True) if feasible[t, d]}
    rows, dets, pair_flips, new = [], [], [], 0
    for d in range(len(kept)):
        if d in matched:
            rows.append(matched[d])
            pair_flips.append(flips[matched[d], d])
        elif kept[d] >= min_joints:
            rows.append(-1)
            pair_flips.append(np.zeros(flips.shape[2], dtype=bool))
            new += 1
        else:
            continue
        dets.append(d)
    as_flips = np.array(pair_flips, dtype=bool).reshape(len(rows), flips.shape[2])
    dropped = len(kept) - len(rows)
    return np.array(rows, dtype=np.int64), np.array(dets, dtype=np.int64), as_flips, new, dropped
