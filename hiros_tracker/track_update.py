"""Track update: a hit track's pose smoothed, its velocities refitted, expired tracks found.

A track keeps, per camera, running least-squares sums of its joints' positions over the
velocity window (a ring of the detections in it): a hit predicts and smooths the pose
(``_hit_one``), moves the window and refits the slopes with one intercept per camera
(``_solve_one``), so that cameras with different clock or calibration offsets do not read as
motion.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hiros_tracker.kernel_args import Hits, TrackFields, UpdateSettings

__all__ = [
    "REBASE_NS",
    "fold_hits",
    "live_tracks",
]


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
def fold_hits(tracks: TrackFields, hits: Hits, settings: UpdateSettings) -> bool:
    """Fold one frame's detections into their tracks (``tracks``' fields, in place).

    Track ``r = hits.rows[u]`` (distinct) takes ``hits.canonical[u]`` ``(J, 3)`` (its detection
    in its labelling, NaN where unmeasured) and the camera's body id ``hits.det_ids[u]``:

    - its pose is predicted and smoothed by ``smoothing`` (1 on its first hit; ``_hit_one``);
    - the detection's least-squares terms enter the camera's running sums and the track's
      ring of records; records older than ``stamp - window_ns`` leave both (every
      ``REBASE_NS`` the time origin moves, see ``_rebase``);
    - its joint and body velocities are refitted from the sums over the cameras of all the
      frame's tracks (``_solve_one``, pooled with ``settings.weights``), where determined.

    Returns:
        whether some track's record ring is now full (the caller grows it before the next frame).

    """
    positions, velocities, velocity = tracks.positions, tracks.velocities, tracks.velocity
    time_ns, last_hit_ns, epoch_ns = tracks.time_ns, tracks.last_hit_ns, tracks.epoch_ns
    n_hits, n_cameras, body_ids, seen = tracks.hits, tracks.n_cameras, tracks.body_ids, tracks.seen
    sums, record_ns, record_camera = tracks.sums, tracks.record_ns, tracks.record_camera
    record_terms, record_start = tracks.record_terms, tracks.record_start
    record_count = tracks.record_count
    rows, canonical, det_ids = hits.rows, hits.canonical, hits.det_ids
    camera, stamp_ns = hits.camera, hits.stamp_ns
    smoothing, max_prediction = settings.smoothing, settings.max_prediction
    window_ns, weights = settings.window_ns, settings.weights
    slots = record_ns.shape[1]
    for u in range(len(rows)):
        r = rows[u]
        slot = (record_start[r] + record_count[r]) % slots
        alpha = smoothing if n_hits[r] else 1.0
        _hit_one(
            positions[r],
            velocity[r],
            time_ns[r],
            epoch_ns[r],
            alpha,
            canonical[u],
            stamp_ns,
            max_prediction,
            record_terms[r, slot],
        )
        time_ns[r] = max(time_ns[r], stamp_ns)
        last_hit_ns[r] = max(last_hit_ns[r], stamp_ns)
        n_hits[r] += 1
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
            _rebase(tracks, r, stamp_ns)
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
def _rebase(tracks: TrackFields, r: int, stamp_ns: int) -> None:
    """Move track ``r``'s time origin to ``stamp_ns`` and rebuild its sums, so ``t²`` stays small.

    A record's terms keep n and p; t, t² and t·p are recomputed for the new origin.
    """
    epoch_ns, sums, record_ns = tracks.epoch_ns, tracks.sums, tracks.record_ns
    record_camera, record_terms = tracks.record_camera, tracks.record_terms
    record_start, record_count = tracks.record_start, tracks.record_count
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
