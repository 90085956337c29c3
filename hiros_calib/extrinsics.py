"""Camera poses from people's joints once the clocks agree (after Eichler et al., 2022, 3.3).

For each camera pair:

1. **Association.** Body tracks overlapping in (corrected) time are paired when their pose
   signatures agree in metres: the same person has the same limb lengths and the same pose at
   the same instant, another person does not. Each track pairs with at most one track of the
   other camera at a time (greedy on the mismatch).
2. **Correspondences.** For every frame of camera a the joints of camera b are interpolated
   at the same reference instant; joints a camera sees badly (low confidence, missing) get
   weight 0 and are left out.
3. **Mirror-proof start.** An SDK seeing a person from behind may swap left and right. The
   midline joints and the midpoints of left/right joint pairs do not change under that swap,
   so a first pose is fitted on them alone: Kabsch (SVD) inside RANSAC, each minimal sample
   taking one point from the torso, one from the arms and one from the legs (body parts
   spread the sample), from different frames.
4. **Per-frame mirror choice.** With that pose, each frame keeps the straight or the
   left/right-swapped correspondence of the full joint set, whichever fits better.
5. **Robust refinement** of all correspondences with ``scipy.optimize.least_squares``
   (``soft_l1`` or ``huber`` loss).

All cameras are then refined jointly (:func:`solve_poses`): every pair's correspondences in
one least-squares problem over all camera poses (reference fixed), so loops close.
Poses are camera -> world with ``p_world = R p_camera + t`` (DESIGN.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from hiros_calib.signature import DEFAULT_JOINTS, pose_signature, select_joints
from hiros_calib.sync import CameraClock
from hiros_calib.tracks import BodyTrack
from hiros_core.geometry import RigidTransform
from hiros_core.layouts import Layout

__all__ = [
    "CameraPose",
    "Correspondences",
    "ExtrinsicsParams",
    "PairPose",
    "associate",
    "estimate_pair_pose",
    "kabsch",
    "pair_correspondences",
    "solve_poses",
]


@dataclass
class ExtrinsicsParams:
    """Parameters of the pose estimation (same names as the ``calib`` node's)."""

    joints: list[str] = field(default_factory=lambda: list(DEFAULT_JOINTS))
    """Joints used as correspondences (names missing from a layout are skipped)."""
    max_signature_mismatch: float = 0.1
    """Largest median signature difference (m) for two tracks to be the same person."""
    max_interpolation_gap: float = 0.1
    """Camera b's frames around an instant must be closer than this (s) to interpolate."""
    inlier_threshold: float = 0.1
    """Distance (m) under which a joint correspondence counts as an inlier."""
    ransac_iterations: int = 400
    """Minimal samples tried per camera pair."""
    loss: str = "soft_l1"
    """Robust loss of the refinement (``soft_l1``, ``huber``, ``cauchy`` or ``linear``)."""
    loss_scale: float = 0.03
    """Residual (m) where the robust loss starts to flatten."""
    max_correspondences: int = 6000
    """Joint correspondences per camera pair kept for the refinements (evenly subsampled)."""
    min_correspondences: int = 30
    """Fewer usable correspondences than this and the pair gives no pose."""
    seed: int = 0
    """Random seed of RANSAC, for repeatable results."""


# --------------------------------------------------------------------------- Kabsch


def kabsch(
    target: np.ndarray, source: np.ndarray, weights: np.ndarray | None = None
) -> RigidTransform:
    """The rigid transform moving ``source (N, 3)`` onto ``target (N, 3)`` (weighted SVD).

    Kabsch (1976) / Umeyama (1991) without scale: minimises ``sum w |R s + t - p|^2``.
    """
    rotation, translation = _kabsch_batch(target[None], source[None], None if weights is None
                                          else weights[None])  # fmt: skip
    return RigidTransform(Rotation.from_matrix(rotation[0]), translation[0])


def _kabsch_batch(
    target: np.ndarray, source: np.ndarray, weights: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Kabsch for ``H`` problems at once: ``(H, N, 3)`` points -> ``(H, 3, 3)``, ``(H, 3)``."""
    if weights is None:
        weights = np.ones(target.shape[:2])
    w = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
    mean_t = (w[..., None] * target).sum(axis=1)
    mean_s = (w[..., None] * source).sum(axis=1)
    cov = np.einsum("hn,hni,hnj->hij", w, target - mean_t[:, None], source - mean_s[:, None])
    u, _, vt = np.linalg.svd(cov)
    sign = np.sign(np.linalg.det(u @ vt))
    sign[sign == 0] = 1.0
    u[:, :, 2] *= sign[:, None]
    rotation = u @ vt
    translation = mean_t - np.einsum("hij,hj->hi", rotation, mean_s)
    return rotation, translation


# --------------------------------------------------------------------------- correspondences


@dataclass
class Correspondences:
    """Joint pairs of one camera pair, structured by frame so a mirror can be applied.

    Attributes:
        points_a: ``(F, K, 3)`` camera a's selected joints (camera a frame).
        points_b: ``(F, K, 3)`` camera b's same-instant joints (camera b frame).
        weights: ``(F, K)`` reliability of each pair (0 = leave out).
        mirror: ``(K,)`` left/right permutation of the selected joints.
        joint_names: ``(K,)`` names of the selected joints.
        groups: ``(K,)`` body part of each joint: 0 torso, 1 arms, 2 legs.
        times: ``(F,)`` camera a's times of the frames.

    """

    points_a: np.ndarray
    points_b: np.ndarray
    weights: np.ndarray
    mirror: np.ndarray
    joint_names: tuple[str, ...]
    groups: np.ndarray
    times: np.ndarray

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return len(self.points_a)

    @staticmethod
    def concatenate(items: list[Correspondences]) -> Correspondences:
        """All frames of several body pairs (same joint selection) in one object."""
        first = items[0]
        return Correspondences(
            np.concatenate([c.points_a for c in items]),
            np.concatenate([c.points_b for c in items]),
            np.concatenate([c.weights for c in items]),
            first.mirror,
            first.joint_names,
            first.groups,
            np.concatenate([c.times for c in items]),
        )


def _body_part(name: str) -> int:
    if any(k in name for k in ("Shoulder", "Elbow", "Wrist", "Hand", "Thumb", "Clavicle")):
        return 1
    if any(k in name for k in ("Hip", "Knee", "Ankle", "Foot")):
        return 2
    return 0


def _joint_tables(layout: Layout, names: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    joints = select_joints(layout, names)
    local = {int(j): k for k, j in enumerate(joints)}
    mirror = np.array([local[int(layout.mirror[j])] for j in joints])
    groups = np.array([_body_part(layout.joint_names[j]) for j in joints])
    return joints, mirror, groups


def _interpolate(track: BodyTrack, times: np.ndarray, max_gap: float) -> tuple[np.ndarray, ...]:
    """Track positions ``(N, J, 3)`` and weights ``(N, J)`` at ``times`` (camera clock)."""
    t = track.times
    idx = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
    gap = t[idx + 1] - t[idx]
    frac = (times - t[idx]) / gap
    inside = (times >= t[0]) & (times <= t[-1]) & (gap <= max_gap)
    frac = np.clip(frac, 0.0, 1.0)[:, None, None]
    positions = track.positions[idx] * (1 - frac) + track.positions[idx + 1] * frac
    weights = np.minimum(track.weights[idx], track.weights[idx + 1])
    weights = np.where(inside[:, None] & np.isfinite(positions).all(axis=2), weights, 0.0)
    return positions, weights


def pair_correspondences(
    track_a: BodyTrack,
    track_b: BodyTrack,
    clock_a: CameraClock,
    clock_b: CameraClock,
    params: ExtrinsicsParams,
) -> Correspondences | None:
    """Same-instant joint pairs of two tracks of the same person, None when they never meet."""
    joints, mirror, groups = _joint_tables(track_a.layout, params.joints)
    t_b = clock_b.from_reference(clock_a.to_reference(track_a.times))
    positions_b, weights_b = _interpolate(track_b, np.asarray(t_b), params.max_interpolation_gap)
    weights = np.minimum(track_a.weights[:, joints], weights_b[:, joints])
    frames = weights.sum(axis=1) > 0
    if frames.sum() < 3:
        return None
    points_a = track_a.positions[frames][:, joints]
    points_b = positions_b[frames][:, joints]
    weights = np.where(np.isfinite(points_a).all(axis=2), weights[frames], 0.0)
    return Correspondences(
        np.nan_to_num(points_a),
        np.nan_to_num(points_b),
        weights,
        mirror,
        tuple(track_a.layout.joint_names[j] for j in joints),
        groups,
        track_a.times[frames],
    )


def associate(
    tracks_a: list[BodyTrack],
    tracks_b: list[BodyTrack],
    clock_a: CameraClock,
    clock_b: CameraClock,
    params: ExtrinsicsParams,
) -> list[tuple[int, int, float]]:
    """Pairs ``(i, j, mismatch m)`` of tracks that are the same person, best first.

    The mismatch is the median over common frames of the weighted mean absolute difference
    of the two pose signatures (metres); signatures need no pose, so this works before any
    extrinsics are known. A track is paired with at most one other track at any instant.
    """
    scored = []
    for i, ta in enumerate(tracks_a):
        joints = select_joints(ta.layout, params.joints)
        sig_a = pose_signature(ta, joints)
        for j, tb in enumerate(tracks_b):
            t_b = np.asarray(clock_b.from_reference(clock_a.to_reference(ta.times)))
            common = (t_b >= tb.start) & (t_b <= tb.end)
            if common.sum() < 10:
                continue
            part_b = BodyTrack(tb.camera, tb.body_id, tb.layout, *_at(tb, t_b[common], params))
            sig_b = pose_signature(part_b, joints)
            w = sig_a.weights[common] * sig_b.weights
            diff = np.abs(np.nan_to_num(sig_a.values[common] - sig_b.values))
            with np.errstate(invalid="ignore", divide="ignore"):
                per_frame = (w * diff).sum(axis=1) / w.sum(axis=1)
            per_frame = per_frame[np.isfinite(per_frame)]
            if len(per_frame) < 10:
                continue
            mismatch = float(np.median(per_frame))
            if mismatch <= params.max_signature_mismatch:
                start, end = float(t_b[common][0]), float(t_b[common][-1])
                scored.append((mismatch, i, j, start, end))
    scored.sort()
    taken_a: dict[int, list[tuple[float, float]]] = {}
    taken_b: dict[int, list[tuple[float, float]]] = {}
    pairs = []
    for mismatch, i, j, start, end in scored:
        # both tracks must be free over this pair's common span (tracks of b are disjoint in
        # time only when ids changed, so the same a track may pair with several b tracks)
        clash = any(s < end and start < e for s, e in taken_a.get(i, [])) or any(
            s < end and start < e for s, e in taken_b.get(j, [])
        )
        if clash:
            continue
        taken_a.setdefault(i, []).append((start, end))
        taken_b.setdefault(j, []).append((start, end))
        pairs.append((i, j, mismatch))
    return pairs


def _at(track: BodyTrack, times: np.ndarray, params: ExtrinsicsParams) -> tuple[np.ndarray, ...]:
    positions, weights = _interpolate(track, times, params.max_interpolation_gap)
    return times, positions, weights


# --------------------------------------------------------------------------- pair pose


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

    """

    camera_a: str
    camera_b: str
    status: str = "refused"
    reason: str = ""
    transform: RigidTransform = field(default_factory=RigidTransform.identity)
    correspondences: Correspondences | None = None
    quality: dict[str, Any] = field(default_factory=dict)

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
    params: ExtrinsicsParams,
    rng: np.random.Generator,
) -> tuple[RigidTransform, np.ndarray]:
    """Kabsch inside RANSAC with minimal samples across body parts; (pose, inlier mask)."""
    n = len(points_a)
    h = params.ransac_iterations
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
    rotation, translation = _kabsch_batch(sample_a, sample_b, None)
    check = rng.choice(n, size=min(n, 3000), replace=False)
    moved = np.einsum("hij,nj->hni", rotation, points_b[check]) + translation[:, None]
    residual = np.linalg.norm(moved - points_a[check][None], axis=2)
    score = ((residual < params.inlier_threshold) * weights[check][None]).sum(axis=1)
    score[area < 0.01] = -1.0
    best = int(np.argmax(score))
    pose = RigidTransform(Rotation.from_matrix(rotation[best]), translation[best])
    inliers = np.zeros(n, dtype=bool)
    for _ in range(3):
        residual = np.linalg.norm(pose.apply(points_b) - points_a, axis=1)
        inliers = residual < params.inlier_threshold
        if inliers.sum() < 3:
            break
        pose = kabsch(points_a[inliers], points_b[inliers], weights[inliers])
    return pose, inliers


def _choose_mirror(c: Correspondences, pose: RigidTransform) -> tuple[np.ndarray, np.ndarray]:
    """Per frame, the straight or swapped b joints, whichever fits; (points_b, weights, swap)."""
    straight = np.linalg.norm(pose.apply(c.points_b) - c.points_a, axis=2)
    swapped = np.linalg.norm(pose.apply(c.points_b[:, c.mirror]) - c.points_a, axis=2)
    w_straight, w_swapped = c.weights, np.minimum(c.weights, c.weights[:, c.mirror])
    cost_straight = _weighted_median_rows(straight, w_straight)
    cost_swapped = _weighted_median_rows(swapped, w_swapped)
    swap = cost_swapped < cost_straight
    return swap, np.where(swap[:, None], w_swapped, w_straight)


def _weighted_median_rows(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Median of each row over entries with positive weight (inf for an empty row)."""
    masked = np.where(weights > 0, values, np.nan)
    with np.errstate(all="ignore"):
        out = np.nanmedian(masked, axis=1) if masked.size else np.empty(0)
    return np.where(np.isfinite(out), out, np.inf)


def _flatten(c: Correspondences, swap: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, ...]:
    """(points_a (N,3), points_b (N,3), weights (N,), joint (N,)) with the mirror applied."""
    points_b = np.where(swap[:, None, None], c.points_b[:, c.mirror], c.points_b)
    joint = np.broadcast_to(np.arange(len(c.mirror))[None], weights.shape)
    valid = weights > 0
    return c.points_a[valid], points_b[valid], weights[valid], joint[valid]


def _subsample(count: int, limit: int) -> np.ndarray:
    if count <= limit:
        return np.arange(count)
    return np.linspace(0, count - 1, limit).round().astype(np.int64)


def _refine_pair(
    points_a: np.ndarray,
    points_b: np.ndarray,
    weights: np.ndarray,
    pose: RigidTransform,
    params: ExtrinsicsParams,
) -> RigidTransform:
    """Robust least-squares refinement of one b -> a pose."""
    root = np.sqrt(weights)[:, None]

    def residuals(x: np.ndarray) -> np.ndarray:
        moved = Rotation.from_rotvec(x[:3]).apply(points_b) + x[3:]
        return ((moved - points_a) * root).ravel()

    x0 = np.concatenate([pose.rotation.as_rotvec(), pose.translation])
    result = least_squares(residuals, x0, loss=params.loss, f_scale=params.loss_scale)
    return RigidTransform(Rotation.from_rotvec(result.x[:3]), result.x[3:])


def estimate_pair_pose(
    correspondences: Correspondences | None,
    params: ExtrinsicsParams,
    *,
    camera_a: str = "a",
    camera_b: str = "b",
) -> PairPose:
    """Camera b's pose in camera a's frame from same-instant joint pairs."""
    if correspondences is None or (correspondences.weights > 0).sum() < params.min_correspondences:
        return PairPose(
            camera_a,
            camera_b,
            reason="the two cameras never see the same person at the same time",
        )
    c = correspondences
    rng = np.random.default_rng(params.seed)
    inv_a, inv_b, inv_w, inv_groups, _ = _invariant_points(c)
    if len(inv_a) < params.min_correspondences:
        return PairPose(camera_a, camera_b, reason="too few reliable joints seen by both cameras")
    pose, inliers = _ransac(inv_a, inv_b, inv_w, inv_groups, params=params, rng=rng)
    if inliers.sum() < params.min_correspondences:
        return PairPose(
            camera_a,
            camera_b,
            reason=f"no consistent pose: only {int(inliers.sum())} of {len(inv_a)} joint pairs "
            f"agree within {params.inlier_threshold * 100:.0f} cm",
        )
    swap, weights = _choose_mirror(c, pose)
    points_a, points_b, w, _ = _flatten(c, swap, weights)
    residual = np.linalg.norm(pose.apply(points_b) - points_a, axis=1)
    inliers = residual < params.inlier_threshold
    pose = kabsch(points_a[inliers], points_b[inliers], w[inliers])
    keep = _subsample(len(points_a), params.max_correspondences)
    pose = _refine_pair(points_a[keep], points_b[keep], w[keep], pose, params)
    swap, weights = _choose_mirror(c, pose)
    chosen = Correspondences(
        c.points_a,
        np.where(swap[:, None, None], c.points_b[:, c.mirror], c.points_b),
        weights,
        c.mirror,
        c.joint_names,
        c.groups,
        c.times,
    )
    points_a, points_b, w, _ = _flatten(chosen, np.zeros(c.n_frames, dtype=bool), weights)
    residual = np.linalg.norm(pose.apply(points_b) - points_a, axis=1)
    inliers = residual < params.inlier_threshold
    quality = {
        "inlier_ratio": round(float(inliers.mean()), 4),
        "residual_m": round(float(np.sqrt(np.mean(residual[inliers] ** 2))), 4),
        "mirrored_fraction": round(float(swap.mean()), 3),
        "correspondences": len(points_a),
    }
    return PairPose(camera_a, camera_b, "ok", "", pose, chosen, quality)


# --------------------------------------------------------------------------- N cameras


@dataclass
class CameraPose:
    """One camera's pose in the world (reference camera) frame, or why it is unknown."""

    camera: str
    status: str = "refused"
    reason: str = ""
    transform: RigidTransform = field(default_factory=RigidTransform.identity)
    quality: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when the pose was determined."""
        return self.status == "ok"


def _spanning_tree(reference: str, pairs: list[PairPose]) -> dict[str, RigidTransform]:
    """Initial camera -> reference poses along the most reliable pairs (Prim's algorithm)."""
    poses = {reference: RigidTransform.identity()}
    remaining = [p for p in pairs if p.ok]
    while True:
        best: tuple[float, str, RigidTransform] | None = None
        for p in remaining:
            strength = p.quality["inlier_ratio"] * p.quality["correspondences"]
            if p.camera_a in poses and p.camera_b not in poses:
                candidate = (strength, p.camera_b, poses[p.camera_a] @ p.transform)
            elif p.camera_b in poses and p.camera_a not in poses:
                candidate = (strength, p.camera_a, poses[p.camera_b] @ p.transform.inverse())
            else:
                continue
            if best is None or candidate[0] > best[0]:
                best = candidate
        if best is None:
            return poses
        poses[best[1]] = best[2]


def solve_poses(
    cameras: list[str],
    reference: str,
    pairs: list[PairPose],
    params: ExtrinsicsParams,
) -> dict[str, CameraPose]:
    """All camera poses at once from every pair's joint correspondences.

    Minimises ``sum rho(|T_a p_a - T_b p_b|^2)`` over every camera pair's correspondences
    (weights applied, reference camera fixed at the identity), starting from the poses
    chained along the most reliable pairs. Cameras no usable pair links to the reference
    are refused with the pairs' reasons.
    """
    initial = _spanning_tree(reference, pairs)
    out = {c: CameraPose(c) for c in cameras}
    for camera in cameras:
        if camera not in initial:
            reasons = [
                f"{p.camera_a}-{p.camera_b}: {p.reason}"
                for p in pairs
                if camera in (p.camera_a, p.camera_b) and not p.ok
            ]
            out[camera].reason = f"cannot link {camera} to the reference {reference}: " + (
                "; ".join(reasons) if reasons else "no camera pair includes it"
            )
    unknown = [c for c in cameras if c in initial and c != reference]
    usable = [
        p
        for p in pairs
        if p.ok and p.correspondences and p.camera_a in initial and p.camera_b in initial
    ]
    blocks = []
    for p in usable:
        points_a, points_b, w, joint = _flatten(
            p.correspondences,
            np.zeros(p.correspondences.n_frames, dtype=bool),
            p.correspondences.weights,
        )
        keep = _subsample(len(points_a), params.max_correspondences)
        blocks.append((p, points_a[keep], points_b[keep], np.sqrt(w[keep])[:, None], joint[keep]))
    index = {c: k for k, c in enumerate(unknown)}

    def pose_of(x: np.ndarray, camera: str) -> tuple[Rotation, np.ndarray]:
        if camera not in index:
            return Rotation.identity(), np.zeros(3)
        k = 6 * index[camera]
        return Rotation.from_rotvec(x[k : k + 3]), x[k + 3 : k + 6]

    def residuals(x: np.ndarray) -> np.ndarray:
        out_rows = []
        for p, points_a, points_b, root, _ in blocks:
            rot_a, t_a = pose_of(x, p.camera_a)
            rot_b, t_b = pose_of(x, p.camera_b)
            out_rows.append((rot_a.apply(points_a) + t_a - rot_b.apply(points_b) - t_b) * root)
        return np.concatenate(out_rows).ravel()

    x0 = np.concatenate(
        [np.r_[initial[c].rotation.as_rotvec(), initial[c].translation] for c in unknown]
    ) if unknown else np.zeros(0)  # fmt: skip
    if unknown:
        x = least_squares(residuals, x0, loss=params.loss, f_scale=params.loss_scale).x
    else:
        x = x0
    for camera in [c for c in cameras if c in initial]:
        rotation, translation = pose_of(x, camera)
        pose = out[camera]
        pose.status, pose.transform = "ok", RigidTransform(rotation, np.asarray(translation))
        pose.quality = _pose_quality(camera, blocks, x, pose_of, params)
    return out


def _pose_quality(
    camera: str,
    blocks: list[tuple[PairPose, np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    x: np.ndarray,
    pose_of: Any,
    params: ExtrinsicsParams,
) -> dict[str, Any]:
    """Residual figures of one camera over the pairs it belongs to, per joint too."""
    residual_parts, joint_parts, names = [], [], ()
    for p, points_a, points_b, _, joint in blocks:
        if camera not in (p.camera_a, p.camera_b):
            continue
        rot_a, t_a = pose_of(x, p.camera_a)
        rot_b, t_b = pose_of(x, p.camera_b)
        diff = rot_a.apply(points_a) + t_a - rot_b.apply(points_b) - t_b
        residual_parts.append(np.linalg.norm(diff, axis=1))
        joint_parts.append(joint)
        names = p.correspondences.joint_names if p.correspondences else ()
    if not residual_parts:
        return {}
    residual, joint = np.concatenate(residual_parts), np.concatenate(joint_parts)
    inliers = residual < params.inlier_threshold
    rms = np.sqrt(np.bincount(joint[inliers], residual[inliers] ** 2, len(names))
                  / np.maximum(np.bincount(joint[inliers], None, len(names)), 1))  # fmt: skip
    return {
        "inlier_ratio": round(float(inliers.mean()), 4),
        "residual_m": round(float(np.sqrt(np.mean(residual[inliers] ** 2))), 4),
        "correspondences": len(residual),
        "joint_residual_m": {n: round(float(r), 4) for n, r in zip(names, rms, strict=True)},
    }


def relative_error(a: RigidTransform, b: RigidTransform) -> tuple[float, float]:
    """(rotation angle in degrees, translation distance in metres) between two poses."""
    angle = math.degrees((a.rotation.inv() * b.rotation).magnitude())
    return angle, float(np.linalg.norm(a.translation - b.translation))
