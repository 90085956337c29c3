"""The merger's compiled fusion (numba): one call per output instead of ~150 numpy calls.

A merged frame holds a few tracks of a few detections of 32 joints: numpy's per-call overhead
dominated. ``merge`` gathers the selected stored detections by track, ``fuse`` weighs and
fuses them (the maths: ``weights.py``, ``robust.py``; stated whole in
numpy in ``test/support/merger_reference.py``, which a property test holds ``fuse`` to), and
``merge`` turns the result into output rows. Sums over cameras run in camera order, sums over
joints pairwise as numpy's are, so results do not depend on how the work is split.

Compiled lazily on first call and cached on disk (``cache=True``): importing this module
compiles nothing. Shapes: ``S`` stored slots, ``K`` cameras, ``M`` tracks, ``C`` slots per
track, ``J`` joints.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hiros_core import compiled
from hiros_core.compiled import _link_rows, refresh_stale_caches
from hiros_merger import numerics, robust, weights
from hiros_merger.kernel_args import (
    BodyLayout,
    CameraTable,
    FuseSettings,
    Fusion,
    MergedFrame,
    StoredDetections,
    TrackDetections,
)
from hiros_merger.numerics import finite3, pairwise_sum
from hiros_merger.robust import final_weights, robust_mean, weighted_means, weighted_median
from hiros_merger.weights import detections_at, facing_weights, known_cameras, occluded

__all__ = ["fuse", "merge"]


@njit(cache=True, error_model="numpy")
def fuse(
    detections: TrackDetections, settings: FuseSettings, body: BodyLayout, up: np.ndarray
) -> Fusion:
    """Fuse the detections of every track (the maths in ``merger.py``'s docstring).

    1. each detection's joints at the output time and their reliability weights
       (``detections_at``);
    2. the weighted median of the cameras' joints (``weighted_median``);
    3. against its front (across the scene's ``up`` ``(3,)``, ``Merger.up``), each flipped
       detection reflected back and the flipped and view factors (``facing_weights``, where
       the layout names the joints of a front) and, with two tracks or more, the occlusion
       factor (``occluded``, where a camera is known);
    4. the robust mean from the median (``robust_mean``), its final weights
       (``final_weights``) and the weighted mean confidences and velocities
       (``weighted_means``).
    """
    weighting = settings.weights
    n_tracks = len(detections.table)
    known = known_cameras(detections.cameras)
    seen = detections_at(detections, weighting, len(body.groups), known)
    fused = weighted_median(seen.positions, seen.weight)
    if body.has_front:
        facing_weights(fused, seen, detections.cameras, known, body, weighting, up)
    if weighting.occlusion_radius > 0 and n_tracks > 1 and known.any():
        occluded(
            fused,
            seen.positions,
            detections.cameras,
            known,
            body.torso,
            weighting.occlusion_radius,
            seen.weight,
            weighting.occlusion_weight,
        )
    _, limb, peak = robust_mean(seen, body.groups, settings.robust, fused)
    final = final_weights(seen.weight, limb, peak, settings.robust)
    confidence, velocity = weighted_means(final, seen.confidences, seen.velocities)
    return Fusion(fused, final, confidence, velocity)


@njit(cache=True, error_model="numpy")
def arrange(tracks: np.ndarray, selected: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
def by_track(
    stored: StoredDetections, table: np.ndarray, out_ns: int, cameras: CameraTable
) -> TrackDetections:
    """The ``table``'s detections with their age (s) and camera position.

    Padding: age 0, position NaN (unknown camera).
    """
    n_tracks, n_slots = table.shape
    ages = np.zeros((n_tracks, n_slots))
    where = np.full((n_tracks, n_slots, 3), np.nan)
    for m in range(n_tracks):
        for c in range(n_slots):
            s = table[m, c]
            if s >= 0:
                camera = stored.cameras[s]
                ages[m, c] = (out_ns - stored.stamps[s]) * 1e-9
                where[m, c] = cameras.positions[camera]
    return TrackDetections(stored.rows, stored.present, table, ages, where)


@njit(cache=True, error_model="numpy")
def output_rows(fusion: Fusion) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Marker rows ``(M, J, 20)``, presence ``(M, J)`` and skeleton confidence ``(M,)``.

    A joint is present where its fused position is finite; its row holds the confidence,
    position and velocity (NaN elsewhere). A skeleton's confidence is the mean of its present
    joints' non-NaN confidences, summed as numpy's ``nanmean`` sums them (NaN: none).
    """
    fused, confidence, velocity = fusion.positions, fusion.confidence, fusion.velocity
    n_tracks, n_joints = confidence.shape
    rows = np.full((n_tracks, n_joints, 20), np.nan)
    present = np.zeros((n_tracks, n_joints), dtype=np.bool_)
    skeleton = np.full(n_tracks, np.nan)
    values = np.empty(n_joints)
    for m in range(n_tracks):
        n_present = n_valued = 0
        for j in range(n_joints):
            if not finite3(fused[m, j, 0], fused[m, j, 1], fused[m, j, 2]):
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
            skeleton[m] = pairwise_sum(values, n_present) / n_valued
    return rows, present, skeleton


@njit(cache=True, error_model="numpy")
def any_orientation(rows: np.ndarray, present: np.ndarray, selected: np.ndarray, n: int) -> bool:
    """Whether a present joint (of the first ``n``) of a ``selected`` slot has an orientation."""
    for s in selected:
        for j in range(n):
            if (
                present[s, j]
                and finite3(rows[s, j, 4], rows[s, j, 5], rows[s, j, 6])
                and math.isfinite(rows[s, j, 7])
            ):
                return True
    return False


@njit(cache=True, error_model="numpy")
def merge(  # noqa: PLR0917 - one output's inputs
    stored: StoredDetections,
    selected: np.ndarray,
    out_ns: int,
    cameras: CameraTable,
    settings: FuseSettings,
    body: BodyLayout,
    up: np.ndarray,
) -> MergedFrame:
    """One output: ``fuse`` the ``selected`` stored slots at ``out_ns``, as output rows.

    The output rows are ``output_rows``', their links ``model.link_rows``' over the layout's
    links.
    """
    track_ids, table = arrange(stored.tracks, selected)
    fusion = fuse(by_track(stored, table, out_ns, cameras), settings, body, up)
    rows, present, skeleton = output_rows(fusion)
    links, link_present = _link_rows(rows, present, body.link_parents, body.link_children)
    oriented = any_orientation(stored.rows, stored.present, selected, len(body.groups))
    return MergedFrame(
        track_ids,
        table,
        fusion.final,
        rows,
        present,
        links,
        link_present,
        skeleton,
        oriented,
    )


# The kernels above call those of these modules (numba's cache sees only this file's edits).
refresh_stale_caches(globals(), compiled, numerics, weights, robust)
