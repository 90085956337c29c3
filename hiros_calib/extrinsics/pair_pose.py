"""One camera pair's pose from its joint correspondences.

An SDK seeing a person from behind may swap left and right. The midline joints and the
midpoints of left/right joint pairs do not change under that swap, so a first pose is
fitted on them alone: Kabsch (SVD) inside RANSAC, each minimal sample taking one point from
the torso, one from the arms and one from the legs, from different frames. With that pose
each frame keeps the straight or the left/right-swapped reading of the full joint set,
whichever fits better, and a robust refinement of all correspondences follows
(:func:`~hiros_calib.extrinsics.robust.robust_solve`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_calib.extrinsics.correspondences import Correspondences, subsample
from hiros_calib.extrinsics.params import (
    FRAME_OUTLIER_RATIO,
    FULL_SAMPLING,
    INLIER_SIGMAS,
    INLIER_THRESHOLD,
    LOSS,
    MAX_CORRESPONDENCES,
    MIN_CORRESPONDENCES,
    RANSAC_CHECKS,
    SEED,
    Sampling,
)
from hiros_calib.extrinsics.robust import (
    Terms,
    flatten_pairs,
    median_rows,
    robust_solve,
    weighted_median_rows,
)
from hiros_core.geometry import RigidTransform, kabsch, kabsch_batch

__all__ = ["PairPose", "baseline_pair_pose", "estimate_pair_pose"]


@dataclass
class PairPose:
    """Camera b's pose in camera a's frame, or why there is none.

    Attributes:
        camera_a, camera_b: the two cameras.
        status: ``"ok"`` or ``"refused"``.
        reason: why it was refused.
        transform: b -> a (``p_a = R p_b + t``).
        correspondences: the joint pairs, with the chosen per-frame mirror applied to b.
        quality: inlier ratio, residual (m), mirrored fraction, correspondences used.
        body_pairs: ``(track_a, track_b)`` indices of the associated same-person tracks.
        reported: the joint pairs as the SDKs reported them (no mirror chosen, weights from
            the confidences only), for baselines and diagnostics.

    """

    camera_a: str
    camera_b: str
    status: str = "refused"
    reason: str = ""
    transform: RigidTransform = field(default_factory=RigidTransform.identity)
    correspondences: Correspondences | None = None
    quality: dict[str, Any] = field(default_factory=dict)
    body_pairs: list[tuple[int, int]] = field(default_factory=list)
    reported: Correspondences | None = None

    @property
    def ok(self) -> bool:
        """True when the pose was determined."""
        return self.status == "ok"


def _invariant_points(c: Correspondences) -> tuple[np.ndarray, ...]:
    """Mirror-invariant points: midline joints and midpoints of left/right pairs.

    Returns ``(N, 3)`` a-points, b-points, weights, body part, frame index.
    """
    keep = np.flatnonzero(np.arange(len(c.mirror)) <= c.mirror)
    partner = c.mirror[keep]
    points_a = 0.5 * (c.points_a[:, keep] + c.points_a[:, partner])
    points_b = 0.5 * (c.points_b[:, keep] + c.points_b[:, partner])
    weights = np.minimum(c.weights[:, keep], c.weights[:, partner])
    frames = np.broadcast_to(np.arange(c.n_frames)[:, None], weights.shape)
    groups = np.broadcast_to(c.groups[keep][None], weights.shape)
    valid = weights > 0
    return points_a[valid], points_b[valid], weights[valid], groups[valid], frames[valid]


def _ransac(
    points_a: np.ndarray,
    points_b: np.ndarray,
    weights: np.ndarray,
    groups: np.ndarray,
    *,
    iterations: int,
    rng: np.random.Generator,
) -> tuple[RigidTransform, np.ndarray]:
    """Kabsch inside RANSAC with minimal samples across body parts; (pose, inlier mask)."""
    n = len(points_a)
    h = iterations
    by_part = [np.flatnonzero(groups == g) for g in range(3)]
    by_part = [idx for idx in by_part if len(idx)]
    if len(by_part) >= 3:
        picks = np.stack([idx[rng.integers(0, len(idx), h)] for idx in by_part[:3]], axis=1)
    else:
        picks = rng.integers(0, n, (h, 3))
    sample_a, sample_b = points_a[picks], points_b[picks]
    # a sample with (nearly) collinear points fixes no rotation: score it out
    area = np.linalg.norm(
        np.cross(sample_b[:, 1] - sample_b[:, 0], sample_b[:, 2] - sample_b[:, 0]), axis=1
    )
    rotation, translation = kabsch_batch(sample_a, sample_b)
    check = rng.choice(n, size=min(n, RANSAC_CHECKS), replace=False)
    moved = np.einsum("hij,nj->hni", rotation, points_b[check]) + translation[:, None]
    residual = np.linalg.norm(moved - points_a[check][None], axis=2)
    score = ((residual < INLIER_THRESHOLD) * weights[check][None]).sum(axis=1)
    score[area < 0.01] = -1.0
    best = int(np.argmax(score))
    pose = RigidTransform(Rotation.from_matrix(rotation[best]), translation[best])
    inliers = np.zeros(n, dtype=bool)
    for _ in range(3):
        residual = np.linalg.norm(pose.apply(points_b) - points_a, axis=1)
        inliers = residual < INLIER_THRESHOLD
        if inliers.sum() < 3:
            break
        pose = kabsch(points_a[inliers], points_b[inliers], weights[inliers])
    return pose, inliers


def baseline_pair_pose(correspondences: Correspondences) -> RigidTransform | None:
    """Camera b's pose in a's frame by Eichler et al. (2022) alone, as a baseline.

    Kabsch inside RANSAC, minimal samples across body parts, on every joint pair as the
    SDKs reported it, then Kabsch on the inliers. None of what :func:`estimate_pair_pose`
    adds: no mirror-proof start or per-frame left/right choice, no frame or joint weights
    from the residuals, no robust refinement, no joint offsets (and, used pair by pair, no
    joint solve over all cameras). None when too few pairs agree.
    """
    c = correspondences
    points_a, points_b, weights, joint, _ = flatten_pairs(c.points_a, c.points_b, c.weights)
    if len(points_a) < MIN_CORRESPONDENCES:
        return None
    rng = np.random.default_rng(SEED)
    iterations = FULL_SAMPLING.ransac_iterations
    pose, inliers = _ransac(
        points_a, points_b, weights, c.groups[joint], iterations=iterations, rng=rng
    )
    return pose if inliers.sum() >= MIN_CORRESPONDENCES else None


def _choose_view(
    c: Correspondences, pose: RigidTransform
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per frame, the reading of both skeletons that fits best.

    Hypotheses: as reported, or b's left and right swapped (an SDK seeing the person from
    behind). Returns the chosen ``points_a``, ``points_b`` (F, K, 3), weights (F, K) and
    the choice (F,): 0 as reported, 1 swapped.
    """
    swapped_w = np.minimum(c.weights, c.weights[:, c.mirror])
    candidates = [
        (c.points_a, c.points_b, c.weights),
        (c.points_a, c.points_b[:, c.mirror], swapped_w),
    ]
    costs = np.stack(
        [
            weighted_median_rows(np.linalg.norm(pose.apply(pb) - pa, axis=2), w)
            for pa, pb, w in candidates
        ]
    )
    choice = np.argmin(costs, axis=0)
    pick = np.arange(c.n_frames)
    points_a = np.stack([pa for pa, _, _ in candidates])[choice, pick]
    points_b = np.stack([pb for _, pb, _ in candidates])[choice, pick]
    weights = np.stack([w for _, _, w in candidates])[choice, pick]
    return points_a, points_b, weights, choice


def _frame_budget(c: Correspondences, sampling: Sampling) -> int:
    """Frames kept for a pair: ``frames_per_minute`` over its time span, at most ``max_frames``."""
    minutes = float(np.ptp(c.times)) / 60.0 if c.n_frames else 0.0
    per_minute = sampling.frames_per_minute
    return int(min(sampling.max_frames, max(per_minute, per_minute * minutes)))


def _refine_pair(
    points_a: np.ndarray,
    points_b: np.ndarray,
    weights: np.ndarray,
    pose: RigidTransform,
    *,
    scale: float,
) -> RigidTransform:
    """Robust least-squares refinement of one b -> a pose (loss flattening at ``scale`` m)."""
    terms = [Terms("a", "b", points_a, points_b, weights, np.zeros_like(points_a))]
    start = {"a": RigidTransform.identity(), "b": pose}
    return robust_solve(start, ["b"], terms, loss=LOSS, scale=scale)["b"]


def estimate_pair_pose(
    correspondences: Correspondences | None,
    *,
    camera_a: str = "a",
    camera_b: str = "b",
    sampling: Sampling = FULL_SAMPLING,
) -> PairPose:
    """Camera b's pose in camera a's frame from same-instant joint pairs.

    ``sampling`` bounds the frames and RANSAC samples drawn on (the quick checks draw fewer).
    """
    if correspondences is None or (correspondences.weights > 0).sum() < MIN_CORRESPONDENCES:
        return PairPose(
            camera_a,
            camera_b,
            reason="the two cameras never see the same person at the same time",
        )
    c = correspondences.take(
        subsample(correspondences.n_frames, _frame_budget(correspondences, sampling))
    )
    rng = np.random.default_rng(SEED)
    inv_a, inv_b, inv_w, inv_groups, _ = _invariant_points(c)
    if len(inv_a) < MIN_CORRESPONDENCES:
        return PairPose(camera_a, camera_b, reason="too few reliable joints seen by both cameras")
    iterations = sampling.ransac_iterations
    pose, inliers = _ransac(inv_a, inv_b, inv_w, inv_groups, iterations=iterations, rng=rng)
    if inliers.sum() < MIN_CORRESPONDENCES:
        return PairPose(
            camera_a,
            camera_b,
            reason=f"no consistent pose: only {int(inliers.sum())} of {len(inv_a)} joint pairs "
            f"agree within {INLIER_THRESHOLD * 100:.0f} cm",
        )
    for _ in range(2):
        chosen_a, chosen_b, weights, _ = _choose_view(c, pose)
        points_a, points_b, w, joint, frame = flatten_pairs(chosen_a, chosen_b, weights)
        keep, scale = _trusted(
            pose, points_a, points_b, joint=joint, frame=frame, n_frames=c.n_frames
        )
        pose = kabsch(points_a[keep], points_b[keep], w[keep])
    sub = subsample(len(points_a), MAX_CORRESPONDENCES)
    sub = sub[keep[sub]]
    pose = _refine_pair(points_a[sub], points_b[sub], w[sub], pose, scale=scale)
    chosen_a, chosen_b, weights, choice = _choose_view(c, pose)
    points_a, points_b, w, joint, frame = flatten_pairs(chosen_a, chosen_b, weights)
    keep, scale = _trusted(pose, points_a, points_b, joint=joint, frame=frame, n_frames=c.n_frames)
    good_frames = np.zeros(c.n_frames, dtype=bool)
    good_frames[frame[keep]] = True
    # inverse-variance weights per joint (the SDK places some joints far less well) and per
    # frame (how well both SDKs see a body changes with the view, and their errors are mostly
    # shared by the whole body in a frame, so the frame's residual spread measures them)
    residual = np.linalg.norm(pose.apply(points_b) - points_a, axis=1)
    table = np.zeros((len(c.mirror), c.n_frames))
    valid = np.zeros(table.shape, dtype=bool)
    table[joint[keep], frame[keep]] = residual[keep]
    valid[joint[keep], frame[keep]] = True
    joint_factor, frame_factor = (
        _inverse_variance(median_rows(values, mask) / 1.54, scale)
        for values, mask in ((table, valid), (table.T, valid.T))
    )
    chosen = Correspondences(
        chosen_a,
        chosen_b,
        np.where(good_frames[:, None], weights * joint_factor * frame_factor[:, None], 0.0),
        c.mirror,
        c.joint_names,
        c.groups,
        c.times,
        c.bodies,
    )
    residual = np.linalg.norm(pose.apply(points_b) - points_a, axis=1)
    quality = {
        "inlier_ratio": round(float(keep.mean()), 4),
        "residual_m": round(float(np.sqrt(np.mean(residual[keep] ** 2))), 4),
        "scale_m": round(scale, 4),
        "mirrored_fraction": round(float((choice == 1).mean()), 3),
        "frames_left_out": round(float(1.0 - good_frames.mean()), 3),
        "correspondences": len(points_a),
    }
    return PairPose(camera_a, camera_b, "ok", "", pose, chosen, quality)


def _inverse_variance(group_scale: np.ndarray, scale: float) -> np.ndarray:
    """Weights ``(scale / group scale)^2``; 0 for groups without any residual (NaN)."""
    return np.where(np.isfinite(group_scale), (scale / np.maximum(group_scale, 1e-4)) ** 2, 0.0)


def _trusted(
    pose: RigidTransform,
    points_a: np.ndarray,
    points_b: np.ndarray,
    *,
    joint: np.ndarray,
    frame: np.ndarray,
    n_frames: int,
) -> tuple[np.ndarray, float]:
    """Inlier mask of the correspondences and the robust residual scale (m).

    The scale is the median residual over 1.54 (the median length of a 3D Gaussian vector
    of unit sigma per axis); frames whose median residual is ``FRAME_OUTLIER_RATIO`` times
    the median of all frames are left out whole.
    """
    residual = np.linalg.norm(pose.apply(points_b) - points_a, axis=1)
    table = np.zeros((n_frames, int(joint.max()) + 1 if joint.size else 1))
    valid = np.zeros(table.shape, dtype=bool)
    table[frame, joint] = residual
    valid[frame, joint] = True
    per_frame = median_rows(table, valid)
    with np.errstate(all="ignore"):
        typical = float(np.nanmedian(per_frame))
    good_frame = per_frame <= FRAME_OUTLIER_RATIO * typical
    in_good = good_frame[frame]
    scale = float(np.median(residual[in_good])) / 1.54 if in_good.any() else typical
    threshold = min(INLIER_THRESHOLD, INLIER_SIGMAS * scale)
    return in_good & (residual < threshold), scale
