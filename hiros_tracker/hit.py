"""One frame's matched pairs folded into their tracks, in one compiled call."""

from __future__ import annotations

import numpy as np
from numba import njit

from hiros_core.compiled import refresh_stale_caches
from hiros_tracker import facing, labels, track_update
from hiros_tracker.facing import turn_facing
from hiros_tracker.kernel_args import (
    FacingView,
    FrameRows,
    HeldSides,
    HitLayout,
    Hits,
    HitSettings,
    TrackFields,
)
from hiros_tracker.labels import canonical_poses, hold_axes, label_frame
from hiros_tracker.track_update import fold_hits

__all__ = [
    "hit_frame",
]


@njit(cache=True, error_model="numpy")
def hit_frame(  # noqa: PLR0917 - the tracks, the frame, its pairs, view, layout, settings
    tracks: TrackFields,
    frame: FrameRows,
    pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
    view: FacingView,
    layout: HitLayout,
    settings: HitSettings,
) -> tuple[np.ndarray, bool, np.ndarray, int, np.ndarray, bool]:
    """One frame's matched pairs folded into their tracks, in one call (``Tracker._hit``).

    In order: the detections in their tracks' labelling (``canonical_poses``), their
    left-right axes folded into their tracks' held ones (``hold_axes``), folded in
    (``fold_hits``), the tracks' facing weighed (``settings.weigh``, ``turn_facing``), and,
    when every track hit is confirmed,
    the output detections labelled in place (``settings.label``, ``label_frame``); a frame
    with tracks to confirm or votes to count leaves that to the caller, which must confirm
    before labelling.

    ``tracks`` changes in place, and ``frame.stacked`` when labelled; ``pairs`` are the
    ``frame_pairs`` rows, detections and flips; ``view`` is the camera's (its code and stamp
    are the frame's).

    Returns:
        ``(U, K)`` the parts relabelled in each detection (its track's swaps included), whether
        a record ring is full (``fold_hits``), ``(U,)`` which tracks turned and how many, the
        ``(U,)`` track ids and whether the detections were labelled.

    """
    rows, dets, flips = pairs
    held = HeldSides(
        tracks.positions,
        tracks.sides,
        tracks.velocity,
        rows,
        layout.body.left,
        layout.body.right,
        tracks.camera_sides,
        tracks.camera_sides_ns,
        view.camera,
        view.stamp_ns,
        tracks.facing,
    )
    canonical, flips = canonical_poses(
        frame.positions, dets, flips, layout.mirror, settings.align, layout.sides, held
    )
    if settings.align and len(layout.body.left):
        hold_axes(held, canonical, tracks.last_hit_ns, view)
    hits = Hits(rows, canonical, frame.det_ids[dets], view.camera, view.stamp_ns)
    full = fold_hits(tracks, hits, settings.update)
    turned = np.zeros(len(rows), dtype=np.bool_)
    if settings.weigh:
        turned = turn_facing(tracks, rows, canonical, view, layout.body, settings.priors)
    n_turned = 0
    for u in range(len(rows)):
        if turned[u]:
            flips[u, :] = ~flips[u, :]
            n_turned += 1
    every = True
    for u in range(len(rows)):
        every &= tracks.confirmed[rows[u]]
    labelled = settings.label and every
    if labelled:
        label_frame(
            frame.stacked,
            frame.index[dets],
            flips,
            layout.mirror,
            tracks.velocities,
            rows,
            tracks.confirmed,
        )
    return flips, full, turned, n_turned, tracks.ids[rows], labelled


refresh_stale_caches(globals(), facing, labels, track_update)  # hit_frame calls their kernels
