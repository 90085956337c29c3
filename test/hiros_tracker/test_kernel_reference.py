"""The association and update kernels held to a numpy statement of their maths, on random input.

The numpy functions below are the readable specification of ``association.match_costs``,
``association.gate_costs`` and the velocity fit of ``track_update.fold_hits``: whole-array
formulas, written from the kernels' docstrings, not from the kernels' loops. Hypothesis draws
the seeds of the random frames (NaN joints, mirrored parts, body ids, unseen tracks).
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hiros_core.layouts import AZURE_KINECT
from hiros_tracker import kernels
from hiros_tracker.kernel_args import (
    GateFrame,
    GateSettings,
    GateTracks,
    Hits,
    MatchSettings,
    TrackPoses,
    UpdateSettings,
)
from hiros_tracker.tracker import _joint_weights, _mirror_parts
from hiros_tracker.tracks import TrackTable

PARTS = _mirror_parts(AZURE_KINECT)
WEIGHTS = _joint_weights(AZURE_KINECT, 0.8)
N_JOINTS = AZURE_KINECT.n_joints
SEEDS = st.integers(0, 2**32 - 1)


def reference_match_costs(  # noqa: PLR0917 - the kernel's inputs, unbundled
    positions: np.ndarray,
    velocity: np.ndarray,
    time_ns: np.ndarray,
    stamp_ns: int,
    detections: np.ndarray,
    settings: MatchSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """``match_costs`` in numpy: ``(T, D)`` weighted mean joint distances, ``(T, D, K)`` flips."""
    part, mirror, n_parts = PARTS.part, PARTS.mirror, PARTS.count
    dt = np.clip((stamp_ns - time_ns) * 1e-9, -settings.max_prediction, settings.max_prediction)
    predicted = positions + velocity[:, None, :] * dt[:, None, None]  # (T, J, 3)
    given_ = np.linalg.norm(predicted[:, None] - detections[None], axis=3)  # (T, D, J)
    mirrored = np.linalg.norm(predicted[:, None] - detections[None][:, :, mirror], axis=3)
    flips = np.zeros((*given_.shape[:2], n_parts), dtype=bool)
    if settings.use_parts:
        for k in range(n_parts):
            in_part = part == k
            mean_given = np.nansum(given_[..., in_part], axis=2) / np.maximum(
                np.isfinite(given_[..., in_part]).sum(axis=2), 1
            )
            count_mirrored = np.isfinite(mirrored[..., in_part]).sum(axis=2)
            mean_mirrored = np.nansum(mirrored[..., in_part], axis=2) / np.maximum(
                count_mirrored, 1
            )
            flips[..., k] = (count_mirrored > 0) & (mean_mirrored + settings.margin < mean_given)
    sided = part >= 0
    take_mirrored = np.zeros(given_.shape, dtype=bool)
    take_mirrored[..., sided] = flips[..., part[sided]]
    chosen = np.where(take_mirrored, mirrored, given_)
    finite = np.isfinite(chosen)
    norm = (finite * WEIGHTS).sum(axis=2)
    total = np.where(finite, chosen * WEIGHTS, 0.0).sum(axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        cost = np.where(norm > 0, total / norm, np.nan)
    cost[finite.sum(axis=2) < settings.min_joints] = np.inf
    return cost, flips


def reference_gate_costs(
    cost: np.ndarray, tracks: GateTracks, frame: GateFrame, settings: GateSettings
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``gate_costs`` in numpy: the finished costs, ``(T, D)`` feasible and ``(T,)`` levels."""
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
    cost = np.where(feasible, cost, kernels.INFEASIBLE)
    recent = tracks.last_hit_ns[:n] >= frame.recent_ns
    levels = np.where(tracks.confirmed[:n], np.where(recent, 0, 1), 2)
    return cost, feasible, levels


def reference_velocities(
    stamps: np.ndarray, cameras: np.ndarray, poses: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The velocity fit over a track's window: one slope per joint, one intercept per camera.

    ``stamps`` ``(N,)`` ns, ``cameras`` ``(N,)``, ``poses`` ``(N, J, 3)`` (NaN: unmeasured).
    The slope of joint ``j`` is ``sum_c sum_i (t_i - tc)(p_i - pc) / sum_c sum_i (t_i - tc)^2``
    (``tc``, ``pc``: camera ``c``'s means of the measured records); the body velocity is the
    ``WEIGHTS`` mean of the numerators over the denominators' ``WEIGHTS`` mean. Returns the
    ``(J, 3)`` slopes, ``(J,)`` the denominators and the ``(3,)`` body velocity.
    """
    t = (stamps - stamps[0]) * 1e-9
    sxx = np.zeros(N_JOINTS)
    sxy = np.zeros((N_JOINTS, 3))
    for camera in np.unique(cameras):
        for j in range(N_JOINTS):
            mine = (cameras == camera) & np.isfinite(poses[:, j]).all(axis=1)
            if not mine.any():
                continue
            dt = t[mine] - t[mine].mean()
            sxx[j] += (dt**2).sum()
            sxy[j] += (dt[:, None] * (poses[mine, j] - poses[mine, j].mean(axis=0))).sum(axis=0)
    determined = sxx > 1e-5
    slopes = np.where(determined[:, None], sxy / np.where(determined, sxx, 1.0)[:, None], 0.0)
    pooled = (sxx * WEIGHTS)[determined].sum()
    body = (sxy * WEIGHTS[:, None])[determined].sum(axis=0) / max(pooled, 1e-12)
    return slopes, sxx, body


def _poses(rng: np.random.Generator, count: int, missing: float) -> np.ndarray:
    """``(count, J, 3)`` random poses near the origin, a share ``missing`` of joints NaN."""
    poses = rng.normal(0.0, 0.5, (count, N_JOINTS, 3)) + rng.normal(0.0, 1.0, (count, 1, 3))
    poses[rng.random((count, N_JOINTS)) < missing] = np.nan
    return poses


@settings(max_examples=40, deadline=None)
@given(seed=SEEDS, use_parts=st.booleans())
def test_match_costs_equal_the_numpy_statement(seed: int, use_parts: bool) -> None:
    rng = np.random.default_rng(seed)
    n_tracks, n_det = rng.integers(0, 5), rng.integers(0, 5)
    tracks = TrackPoses(
        _poses(rng, n_tracks, 0.1),
        rng.normal(0.0, 1.0, (n_tracks, 3)),
        rng.integers(0, 400_000_000, n_tracks),
    )
    detections = _poses(rng, n_det, 0.3)
    if n_tracks and n_det:  # a track seen mirrored: its parts must come out flipped
        detections[0] = tracks.positions[0][PARTS.mirror] + rng.normal(0.0, 0.01, (N_JOINTS, 3))
    match = MatchSettings(0.2, use_parts, int(rng.integers(1, 20)), float(rng.random() * 0.1))
    stamp = 300_000_000
    cost, flips = kernels.match_costs(tracks, detections, stamp, WEIGHTS, PARTS.arrays, match)
    want_cost, want_flips = reference_match_costs(
        tracks.positions, tracks.velocity, tracks.time_ns, stamp, detections, match
    )
    np.testing.assert_array_equal(flips, want_flips)
    np.testing.assert_allclose(cost, want_cost, rtol=1e-12, atol=0.0)


@settings(max_examples=40, deadline=None)
@given(seed=SEEDS, bonus=st.sampled_from([0.0, 0.3]))
def test_gate_costs_equal_the_numpy_statement(seed: int, bonus: float) -> None:
    rng = np.random.default_rng(seed)
    n_tracks, n_det, n_cameras = rng.integers(0, 6), rng.integers(0, 6), 3
    cost = rng.random((n_tracks, n_det)) * 2.0
    cost[rng.random(cost.shape) < 0.2] = np.inf
    tracks = GateTracks(
        rng.integers(0, 2_000_000_000, n_tracks + 2),  # the table's rows past n are not read
        rng.random(n_tracks + 2) < 0.6,
        rng.integers(-1, 4, (n_tracks + 2, n_cameras)),
        rng.random((n_tracks + 2, n_cameras)) < 0.7,
    )
    frame = GateFrame(rng.integers(-1, 4, n_det), 1, 2_000_000_000, 1_500_000_000)
    gate = GateSettings(bonus, 0.8, 2.0)
    want = reference_gate_costs(cost, tracks, frame, gate)
    feasible, levels = kernels.gate_costs(cost, tracks, frame, gate)  # finishes cost in place
    np.testing.assert_array_equal(cost, want[0])
    np.testing.assert_array_equal(feasible, want[1])
    np.testing.assert_array_equal(levels, want[2])


@settings(max_examples=25, deadline=None)
@given(seed=SEEDS)
def test_fold_hits_fits_the_velocities_of_the_numpy_statement(seed: int) -> None:
    """Detections of one moving track from three cameras (offset from each other) folded in."""
    rng = np.random.default_rng(seed)
    velocity = rng.normal(0.0, 1.0, 3)
    offsets = rng.normal(0.0, 0.05, (3, 1, 3))  # each camera's own calibration error
    base = _poses(rng, 1, 0.0)[0]
    window_ns = 250_000_000
    update = UpdateSettings(0.5, 0.2, window_ns, WEIGHTS)
    count = int(rng.integers(6, 20))
    stamps = np.cumsum(rng.integers(5_000_000, 30_000_000, count)) + 1_000_000_000
    cameras = rng.integers(0, 3, count)
    poses = base + velocity * ((stamps - stamps[0]) * 1e-9)[:, None, None] + offsets[cameras]
    poses += rng.normal(0.0, 0.01, poses.shape)
    poses[rng.random(poses.shape[:2]) < 0.1] = np.nan
    table = TrackTable(N_JOINTS, 3)
    row = table.add(0, base, int(stamps[0]))
    for stamp, camera, pose in zip(stamps.tolist(), cameras.tolist(), poses, strict=True):
        hits = Hits(np.array([row]), pose[None], np.array([7]), camera, stamp)
        if kernels.fold_hits(table.hit_fields(), hits, update):
            table.grow_records()
    inside = stamps >= stamps[-1] - window_ns
    slopes, sxx, body = reference_velocities(stamps[inside], cameras[inside], poses[inside])
    determined = sxx > 1e-4  # clear of the kernel's 1e-5 cut either way
    np.testing.assert_allclose(table.velocities[row][determined], slopes[determined], atol=1e-6)
    if ((sxx > 1e-4) | (sxx < 1e-6)).all():  # no joint near the cut: the same joints pooled
        np.testing.assert_allclose(table.velocity[row], body, atol=1e-6)
