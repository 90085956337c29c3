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
5. **Robust refinement** of all correspondences: Gauss-Newton with iteratively reweighted
   least squares on the robust loss (``soft_l1``, ``huber``, ``cauchy`` or ``linear``) of
   each 3D residual, analytic Jacobians (:func:`_robust_solve`).

All cameras are then refined jointly (:func:`solve_poses`): every pair's correspondences in
one least-squares problem over all camera poses (reference fixed), so loops close.
Poses are camera -> world with ``p_world = R p_camera + t`` (DESIGN.md).

What limits the accuracy is the data, not a bias of these steps: the SDKs' joint errors
(mostly one shift of the whole body per frame, and fixed per-person joint offsets) and their
larger error on bodies seen from the side. The experiments behind that, and what was tried
without gain, are in ``docs/pose-accuracy.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_calib.signature import DEFAULT_JOINTS, pose_signature, select_joints
from hiros_calib.sync import CameraClock
from hiros_calib.tracks import BodyTrack
from hiros_core.geometry import RigidTransform, kabsch, kabsch_batch
from hiros_core.layouts import Layout

__all__ = [
    "CameraPose",
    "Correspondences",
    "ExtrinsicsParams",
    "PairPose",
    "associate",
    "baseline_pair_pose",
    "estimate_pair_pose",
    "kabsch",
    "pair_correspondences",
    "solve_poses",
]

SPLIT_BLOCK = 2.0
"""Length (s) of the alternating spans of time that make the two halves of a pose's check
(and the two folds of a lag's cross-validated fit, :mod:`~hiros_calib.lags`): longer than
the SDKs' error correlation, so one half's frames are not near copies of the other's."""


def second_half(times: np.ndarray) -> np.ndarray:
    """Which of two halves each instant (s) falls in: alternating ``SPLIT_BLOCK`` spans."""
    return (np.floor(times / SPLIT_BLOCK).astype(np.int64) % 2).astype(bool)


@dataclass
class ExtrinsicsParams:
    """Parameters of the pose estimation (same names as the ``calib`` node's)."""

    joints: list[str] = field(default_factory=lambda: list(DEFAULT_JOINTS))
    """Joints whose distances identify a person across cameras (see signature.py)."""
    max_signature_mismatch: float = 0.1
    """Largest median signature difference (m) for two tracks to be the same person."""
    min_common_time: float = 2.0
    """Two tracks must be seen together this long (s) to be paired (short ghosts are not)."""
    association_frames: int = 300
    """Common instants (evenly subsampled) over which two tracks' signatures are compared."""
    pose_joints: list[str] = field(default_factory=list)
    """Joints used as correspondences; empty = every joint of the layout (more joints
    average out more of the SDK's fixed per-joint errors)."""
    max_interpolation_gap: float = 0.1
    """Camera b's frames around an instant must be closer than this (s) to interpolate."""
    inlier_threshold: float = 0.25
    """Largest distance (m) for a joint correspondence to count as an inlier; the working
    threshold adapts to the data's spread (``inlier_sigmas`` times the robust scale)."""
    inlier_sigmas: float = 3.0
    """Inliers lie within this many robust residual scales (median residual / 1.54)."""
    frame_outlier_ratio: float = 2.5
    """Frames whose median residual exceeds this times the typical one are left out (an
    SDK that took the back for the front moves every limb)."""
    ransac_iterations: int = 400
    """Minimal samples tried per camera pair."""
    ransac_checks: int = 1000
    """Correspondences (random) each RANSAC sample is scored on."""
    loss: str = "soft_l1"
    """Robust loss of the refinements (``soft_l1``, ``huber``, ``cauchy`` or ``linear``), on
    the length of each joint's 3D residual."""
    loss_scale: float = 0.0
    """Residual (m) where the robust loss starts to flatten; 0 = the data's robust scale."""
    joint_offset_rounds: int = 3
    """Rounds of estimating the fixed per-person, per-joint disagreement between two
    cameras' SDKs alternately with the poses (0: assume the SDKs agree on average)."""
    offset_shrinkage: float = 30.0
    """Samples' worth of pull towards 0 on each joint offset, so short tracks stay sane."""
    max_correspondences: int = 200000
    """Joint correspondences per camera pair kept for the refinements (evenly subsampled);
    the default keeps every joint of the frames kept: on the simulator, keeping a fifth of
    them gave about 6 % more rotation error."""
    frame_weights: bool = True
    """Weight each frame by the inverse of its residual variance (the SDKs' error changes
    with the view; on the simulator about 4 % less rotation error than equal weights)."""
    frames_per_minute: float = 1000.0
    """Frames (body pairs at one instant) per camera pair and minute of recording kept for
    the pose, evenly subsampled. The SDK's errors are correlated over about 0.2 s, so at 30 Hz
    neighbouring frames add little information; but a count that does not grow with the
    recording wastes a long one (on the simulator, 3 minutes: 0.34 deg with 1000 frames in
    all, 0.28-0.30 deg with 1000 a minute; 1 minute: no better with 3000)."""
    max_frames: int = 10000
    """At most this many frames per camera pair, whatever the length (bounds the cost)."""
    min_correspondences: int = 30
    """Fewer usable correspondences than this and the pair gives no pose."""
    seed: int = 0
    """Random seed of RANSAC, for repeatable results."""


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
    bodies: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __post_init__(self) -> None:
        if len(self.bodies) != len(self.points_a):
            self.bodies = np.zeros(len(self.points_a), dtype=np.int64)

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return len(self.points_a)

    def take(self, frames: np.ndarray) -> Correspondences:
        """The correspondences of the given frames (indices, in order)."""
        return Correspondences(
            self.points_a[frames],
            self.points_b[frames],
            self.weights[frames],
            self.mirror,
            self.joint_names,
            self.groups,
            self.times[frames],
            self.bodies[frames],
        )

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
            np.concatenate([np.full(c.n_frames, k, dtype=np.int64) for k, c in enumerate(items)]),
        )


def _body_part(name: str) -> int:
    if any(k in name for k in ("Shoulder", "Elbow", "Wrist", "Hand", "Thumb", "Clavicle")):
        return 1
    if any(k in name for k in ("Hip", "Knee", "Ankle", "Foot")):
        return 2
    return 0


def _joint_tables(layout: Layout, names: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Selected joints, their mirror permutation (local indices) and body parts."""
    joints = select_joints(layout, names)
    local = {int(j): k for k, j in enumerate(joints)}
    mirror = np.array([local[int(layout.mirror[j])] for j in joints])
    groups = np.array([_body_part(layout.joint_names[j]) for j in joints])
    return joints, mirror, groups


def pair_correspondences(
    track_a: BodyTrack,
    track_b: BodyTrack,
    clock_a: CameraClock,
    clock_b: CameraClock,
    params: ExtrinsicsParams,
) -> Correspondences | None:
    """Same-instant joint pairs of two tracks of the same person, None when they never meet."""
    joints, mirror, groups = _joint_tables(track_a.layout, params.pose_joints)
    t_b = clock_b.from_reference(clock_a.to_reference(track_a.times))
    positions_b, weights_b = track_b.at(np.asarray(t_b), params.max_interpolation_gap)
    weights = np.minimum(track_a.weights[:, joints], weights_b[:, joints]) ** 2
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
            common = np.flatnonzero((t_b >= tb.start) & (t_b <= tb.end))
            if len(common) < 10 or t_b[common[-1]] - t_b[common[0]] < params.min_common_time:
                continue
            start, end = float(t_b[common[0]]), float(t_b[common[-1]])
            # a median over a few hundred instants tells people apart as well as all of them
            common = common[_subsample(len(common), params.association_frames)]
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
    positions, weights = track.at(times, params.max_interpolation_gap)
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
    rotation, translation = kabsch_batch(sample_a, sample_b)
    check = rng.choice(n, size=min(n, params.ransac_checks), replace=False)
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


def baseline_pair_pose(
    correspondences: Correspondences, params: ExtrinsicsParams | None = None
) -> RigidTransform | None:
    """Camera b's pose in a's frame by Eichler et al. (2022) alone, as a baseline.

    Kabsch inside RANSAC, minimal samples across body parts, on every joint pair as the
    SDKs reported it, then Kabsch on the inliers. None of what :func:`estimate_pair_pose`
    adds: no mirror-proof start or per-frame left/right choice, no frame or joint weights
    from the residuals, no robust refinement, no joint offsets (and, used pair by pair, no
    joint solve over all cameras). None when too few pairs agree.
    """
    params = params or ExtrinsicsParams()
    c = correspondences
    points_a, points_b, weights, joint, _ = _flatten(c.points_a, c.points_b, c.weights)
    if len(points_a) < params.min_correspondences:
        return None
    rng = np.random.default_rng(params.seed)
    pose, inliers = _ransac(points_a, points_b, weights, c.groups[joint], params=params, rng=rng)
    return pose if inliers.sum() >= params.min_correspondences else None


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
            _weighted_median_rows(np.linalg.norm(pose.apply(pb) - pa, axis=2), w)
            for pa, pb, w in candidates
        ]
    )
    choice = np.argmin(costs, axis=0)
    pick = np.arange(c.n_frames)
    points_a = np.stack([pa for pa, _, _ in candidates])[choice, pick]
    points_b = np.stack([pb for _, pb, _ in candidates])[choice, pick]
    weights = np.stack([w for _, _, w in candidates])[choice, pick]
    return points_a, points_b, weights, choice


def _weighted_median_rows(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Median of each row over entries with positive weight (inf for an empty row)."""
    out = _median_rows(values, weights > 0)
    return np.where(np.isfinite(out), out, np.inf)


def _median_rows(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Median of each row of ``(R, K)`` over its ``valid`` entries (NaN for an empty row).

    One sort of the whole table instead of ``np.nanmedian``, which is many times slower on
    short rows.
    """
    if values.size == 0:
        return np.full(len(values), np.nan)
    ordered = np.sort(np.where(valid, values, np.inf), axis=1)
    count = valid.sum(axis=1)
    rows = np.arange(len(values))
    low = ordered[rows, np.maximum(count - 1, 0) // 2]
    high = ordered[rows, np.maximum(count // 2, 0) - (count == 0)]
    with np.errstate(invalid="ignore"):
        return np.where(count > 0, 0.5 * (low + high), np.nan)


def _flatten(
    points_a: np.ndarray, points_b: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, ...]:
    """(points_a, points_b, weights, joint, frame) rows of the pairs with positive weight."""
    joint = np.broadcast_to(np.arange(weights.shape[1])[None], weights.shape)
    frame = np.broadcast_to(np.arange(weights.shape[0])[:, None], weights.shape)
    valid = weights > 0
    return points_a[valid], points_b[valid], weights[valid], joint[valid], frame[valid]


def _frame_budget(c: Correspondences, params: ExtrinsicsParams) -> int:
    """Frames kept for a pair: ``frames_per_minute`` over its time span, at most ``max_frames``."""
    minutes = float(np.ptp(c.times)) / 60.0 if c.n_frames else 0.0
    return int(
        min(params.max_frames, max(params.frames_per_minute, params.frames_per_minute * minutes))
    )


def _subsample(count: int, limit: int) -> np.ndarray:
    if count <= limit:
        return np.arange(count)
    return np.linspace(0, count - 1, limit).round().astype(np.int64)


def _loss_weights(z: np.ndarray, loss: str) -> np.ndarray:
    """IRLS weight ``rho'(z)`` of a residual with squared scaled norm ``z = |r|^2 / s^2``."""
    if loss == "soft_l1":
        return 1.0 / np.sqrt(1.0 + z)
    if loss == "huber":
        return np.where(z <= 1.0, 1.0, 1.0 / np.sqrt(np.maximum(z, 1.0)))
    if loss == "cauchy":
        return 1.0 / (1.0 + z)
    if loss == "linear":
        return np.ones_like(z)
    msg = f"unknown loss {loss!r}: use soft_l1, huber, cauchy or linear"
    raise ValueError(msg)


def _normal_block(w: np.ndarray, q: np.ndarray, other: np.ndarray) -> np.ndarray:
    """``sum w J^T J'`` for Jacobians ``J = [-[q]_x, I]``, ``J' = [-[q']_x, I]`` (6 x 6).

    Written with weighted moments of the points, so nothing of size ``N x 3 x 6`` is built.
    """
    moment = np.einsum("n,ni,nj->ij", w, other, q)  # sum w q' q^T
    block = np.empty((6, 6))
    block[:3, :3] = np.trace(moment) * np.eye(3) - moment
    block[:3, 3:] = _skew(np.einsum("n,ni->i", w, q))
    block[3:, :3] = -_skew(np.einsum("n,ni->i", w, other))
    block[3:, 3:] = w.sum() * np.eye(3)
    return block


def _skew(v: np.ndarray) -> np.ndarray:
    """The matrix ``[v]_x`` of the cross product with ``v``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@dataclass
class _Terms:
    """One set of correspondences ``T_a p_a - T_b p_b - offset`` of the robust solve."""

    camera_a: str
    camera_b: str
    points_a: np.ndarray
    points_b: np.ndarray
    weights: np.ndarray
    offsets: np.ndarray  # (N, 3) world frame, 0 when not modelled


def _robust_solve(
    poses: dict[str, RigidTransform],
    unknown: list[str],
    terms: list[_Terms],
    *,
    loss: str,
    scale: float,
    iterations: int = 100,
    tolerance: float = 1e-8,
) -> dict[str, RigidTransform]:
    """Poses of the ``unknown`` cameras minimising ``sum w rho(|T_a p_a - T_b p_b - d|^2/s^2)``.

    Gauss-Newton with iteratively reweighted least squares: each step solves the weighted
    normal equations of the linearised residuals (analytic Jacobian, rotations perturbed on
    the left, ``R <- exp(w) R``), the weights being the loss's influence at the current
    residuals. The loss acts on each 3D residual's length, so the estimate does not depend
    on how the world axes are oriented. A few small dense ``6U x 6U`` solves replace a generic
    solver's finite-difference Jacobians of the whole residual vector.
    """
    poses = dict(poses)
    column = {camera: 6 * k for k, camera in enumerate(unknown)}
    size = 6 * len(unknown)
    if not size:
        return poses
    for _ in range(iterations):
        hessian = np.zeros((size, size))
        gradient = np.zeros(size)
        for t in terms:
            moved_a = poses[t.camera_a].rotation.apply(t.points_a)
            moved_b = poses[t.camera_b].rotation.apply(t.points_b)
            residual = (
                moved_a + poses[t.camera_a].translation
                - moved_b - poses[t.camera_b].translation - t.offsets
            )  # fmt: skip
            z = np.einsum("ni,ni->n", residual, residual) / scale**2
            w = t.weights * _loss_weights(z, loss)
            # normal equations of the unknown cameras' (rotation, translation) perturbations
            moving = [
                (column[camera], moved, sign)
                for camera, moved, sign in ((t.camera_a, moved_a, 1.0), (t.camera_b, moved_b, -1.0))
                if camera in column
            ]
            for k, moved, sign in moving:
                gradient[k : k + 3] += sign * np.einsum("n,ni->i", w, np.cross(moved, residual))
                gradient[k + 3 : k + 6] += sign * np.einsum("n,ni->i", w, residual)
                for m, other, other_sign in moving:
                    hessian[k : k + 6, m : m + 6] += (
                        sign * other_sign * _normal_block(w, moved, other)
                    )
        step = -np.linalg.solve(hessian + 1e-12 * np.eye(size), gradient)
        for camera, k in column.items():
            pose = poses[camera]
            poses[camera] = RigidTransform(
                Rotation.from_rotvec(step[k : k + 3]) * pose.rotation,
                pose.translation + step[k + 3 : k + 6],
            )
        if np.abs(step).max() < tolerance:
            break
    return poses


def _refine_pair(
    points_a: np.ndarray,
    points_b: np.ndarray,
    weights: np.ndarray,
    pose: RigidTransform,
    *,
    scale: float,
    params: ExtrinsicsParams,
) -> RigidTransform:
    """Robust least-squares refinement of one b -> a pose (loss flattening at ``scale`` m)."""
    terms = [_Terms("a", "b", points_a, points_b, weights, np.zeros_like(points_a))]
    start = {"a": RigidTransform.identity(), "b": pose}
    return _robust_solve(start, ["b"], terms, loss=params.loss, scale=scale)["b"]


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
    c = correspondences.take(
        _subsample(correspondences.n_frames, _frame_budget(correspondences, params))
    )
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
    for _ in range(2):
        chosen_a, chosen_b, weights, _ = _choose_view(c, pose)
        points_a, points_b, w, joint, frame = _flatten(chosen_a, chosen_b, weights)
        keep, scale = _trusted(
            pose, points_a, points_b, joint=joint, frame=frame, n_frames=c.n_frames, params=params
        )
        pose = kabsch(points_a[keep], points_b[keep], w[keep])
    sub = _subsample(len(points_a), params.max_correspondences)
    sub = sub[keep[sub]]
    pose = _refine_pair(
        points_a[sub],
        points_b[sub],
        w[sub],
        pose,
        scale=params.loss_scale or scale,
        params=params,
    )
    chosen_a, chosen_b, weights, choice = _choose_view(c, pose)
    points_a, points_b, w, joint, frame = _flatten(chosen_a, chosen_b, weights)
    keep, scale = _trusted(
        pose, points_a, points_b, joint=joint, frame=frame, n_frames=c.n_frames, params=params
    )
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
        _inverse_variance(_median_rows(values, mask) / 1.54, scale)
        for values, mask in ((table, valid), (table.T, valid.T))
    )
    if not params.frame_weights:
        frame_factor = np.ones(c.n_frames)
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
    params: ExtrinsicsParams,
) -> tuple[np.ndarray, float]:
    """Inlier mask of the correspondences and the robust residual scale (m).

    The scale is the median residual over 1.54 (the median length of a 3D Gaussian vector
    of unit sigma per axis); frames whose median residual is ``frame_outlier_ratio`` times
    the median of all frames are left out whole.
    """
    residual = np.linalg.norm(pose.apply(points_b) - points_a, axis=1)
    table = np.zeros((n_frames, int(joint.max()) + 1 if joint.size else 1))
    valid = np.zeros(table.shape, dtype=bool)
    table[frame, joint] = residual
    valid[frame, joint] = True
    per_frame = _median_rows(table, valid)
    with np.errstate(all="ignore"):
        typical = float(np.nanmedian(per_frame))
    good_frame = per_frame <= params.frame_outlier_ratio * typical
    in_good = good_frame[frame]
    scale = float(np.median(residual[in_good])) / 1.54 if in_good.any() else typical
    threshold = min(params.inlier_threshold, params.inlier_sigmas * scale)
    return in_good & (residual < threshold), scale


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


@dataclass
class _Block:
    """One camera pair's correspondences in the joint solve.

    ``label`` numbers the (body pair, joint) each row belongs to; ``offsets (L, 3)`` are the
    fixed disagreements (world frame, m) the two SDKs have about that joint of that person;
    ``times`` is each row's instant (s, camera a's clock).
    """

    pair: PairPose
    points_a: np.ndarray
    points_b: np.ndarray
    weights: np.ndarray
    joint: np.ndarray
    label: np.ndarray
    offsets: np.ndarray
    times: np.ndarray

    def difference(self, poses: dict[str, RigidTransform]) -> np.ndarray:
        """``(N, 3)`` T_a p_a - T_b p_b - offset, world frame."""
        pose_a, pose_b = poses[self.pair.camera_a], poses[self.pair.camera_b]
        return pose_a.apply(self.points_a) - pose_b.apply(self.points_b) - self.offsets[self.label]

    def terms(self, rows: np.ndarray | None = None) -> _Terms:
        """The block (or its ``rows``) as terms of :func:`_robust_solve`, offsets as they are."""
        rows = slice(None) if rows is None else rows
        return _Terms(
            self.pair.camera_a,
            self.pair.camera_b,
            self.points_a[rows],
            self.points_b[rows],
            self.weights[rows],
            self.offsets[self.label[rows]],
        )

    def update_offsets(
        self, poses: dict[str, RigidTransform], scale: float, shrink: float, loss: str
    ) -> None:
        """Robust per-label mean residual, shrunk towards 0 and centred (weighted mean 0).

        Centring keeps the offsets from absorbing the translation: only how the SDKs
        disagree from joint to joint and person to person is modelled, not their average.
        """
        self.offsets[:] = 0.0
        residual = self.difference(poses)
        norm2 = (residual**2).sum(axis=1) / scale**2
        weight = self.weights * _loss_weights(norm2, loss)
        count = np.bincount(self.label, weight, len(self.offsets))
        sums = np.stack(
            [np.bincount(self.label, weight * residual[:, k], len(self.offsets)) for k in range(3)],
            axis=1,
        )
        offsets = sums / (count + shrink * float(np.median(self.weights)))[:, None]
        mean = (weight[:, None] * offsets[self.label]).sum(axis=0) / max(weight.sum(), 1e-12)
        self.offsets[:] = offsets - mean


def solve_poses(
    cameras: list[str],
    reference: str,
    pairs: list[PairPose],
    params: ExtrinsicsParams,
) -> dict[str, CameraPose]:
    """All camera poses at once from every pair's joint correspondences.

    Minimises ``sum rho(|T_a p_a - T_b p_b - d|^2)`` over every camera pair's correspondences
    (weights applied, reference camera fixed at the identity), starting from the poses
    chained along the most reliable pairs. ``d`` are per (person, joint) offsets, estimated
    alternately with the poses (``joint_offset_rounds``): SDKs place a given person's joint a
    few centimetres differently in each camera for the whole recording, and left unmodelled
    those fixed disagreements tilt the solution. Cameras no usable pair links to the
    reference are refused with the pairs' reasons.
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
    blocks = [
        _block(p, params)
        for p in pairs
        if p.ok and p.correspondences and p.camera_a in initial and p.camera_b in initial
    ]
    poses = {c: initial[c] for c in cameras if c in initial}
    scale = params.loss_scale or float(
        np.median([b.pair.quality["scale_m"] for b in blocks]) if blocks else 0.05
    )
    if unknown:
        for round_index in range(params.joint_offset_rounds + 1):
            if round_index:
                for block in blocks:
                    block.update_offsets(poses, scale, params.offset_shrinkage, params.loss)
            poses = _robust_solve(
                poses, unknown, [b.terms() for b in blocks], loss=params.loss, scale=scale
            )
    spreads = _split_half_spreads(poses, unknown, blocks, scale, params)
    for camera, transform in poses.items():
        pose = out[camera]
        pose.status, pose.transform = "ok", transform
        pose.quality = _pose_quality(camera, blocks, poses, params)
        if camera in spreads:
            pose.quality["pose_split_deg"] = round(spreads[camera][0], 3)
            pose.quality["pose_split_cm"] = round(100 * spreads[camera][1], 2)
    return out


def _split_half_spreads(
    poses: dict[str, RigidTransform],
    unknown: list[str],
    blocks: list[_Block],
    scale: float,
    params: ExtrinsicsParams,
) -> dict[str, tuple[float, float]]:
    """How far apart (deg, m) each camera's pose lies when solved on two halves of the data.

    The halves are alternating ``SPLIT_BLOCK`` spans of time, so each sees the recording's
    variety; each is solved like the whole (every pair at once, the SDKs' joint offsets as
    the whole found them), starting from the whole's poses. Each half's error is about
    sqrt(2) times the whole's and their difference sqrt(2) times a half's, so half the spread
    estimates the error of the camera's final pose, loops included (an error every frame
    shares stays hidden). Cameras with too little data in either half are left out.
    """
    halves = []
    for parity in (0, 1):
        rows = [second_half(b.times) == parity for b in blocks]
        enough = {
            camera
            for camera in unknown
            if sum(
                int(r.sum()) for b, r in zip(blocks, rows, strict=True)
                if camera in (b.pair.camera_a, b.pair.camera_b)
            ) >= params.min_correspondences
        }  # fmt: skip
        if not enough:
            return {}
        terms = [b.terms(r) for b, r in zip(blocks, rows, strict=True) if r.any()]
        solved = _robust_solve(poses, sorted(enough), terms, loss=params.loss, scale=scale)
        halves.append({c: solved[c] for c in enough})
    return {
        camera: relative_error(halves[0][camera], halves[1][camera])
        for camera in halves[0].keys() & halves[1].keys()
    }


def _block(pair: PairPose, params: ExtrinsicsParams) -> _Block:
    c = pair.correspondences
    assert c is not None
    points_a, points_b, w, joint, frame = _flatten(c.points_a, c.points_b, c.weights)
    keep = _subsample(len(points_a), params.max_correspondences)
    n_joints = len(c.mirror)
    label = c.bodies[frame[keep]] * n_joints + joint[keep]
    n_labels = (int(c.bodies.max()) + 1) * n_joints if c.n_frames else 1
    return _Block(
        pair,
        points_a[keep],
        points_b[keep],
        w[keep],
        joint[keep],
        label,
        np.zeros((n_labels, 3)),
        c.times[frame[keep]],
    )


def _pose_quality(
    camera: str,
    blocks: list[_Block],
    poses: dict[str, RigidTransform],
    params: ExtrinsicsParams,
) -> dict[str, Any]:
    """Residual figures of one camera over the pairs it belongs to, per joint too."""
    mine = [b for b in blocks if camera in (b.pair.camera_a, b.pair.camera_b)]
    if not mine:
        return {}
    names = mine[0].pair.correspondences.joint_names if mine[0].pair.correspondences else ()
    residual = np.concatenate([np.linalg.norm(b.difference(poses), axis=1) for b in mine])
    joint = np.concatenate([b.joint for b in mine])
    offsets = np.concatenate([np.linalg.norm(b.offsets, axis=1) for b in mine])
    scale = float(np.median(residual)) / 1.54
    inliers = residual < min(params.inlier_threshold, params.inlier_sigmas * scale)
    rms = np.sqrt(np.bincount(joint[inliers], residual[inliers] ** 2, len(names))
                  / np.maximum(np.bincount(joint[inliers], None, len(names)), 1))  # fmt: skip
    return {
        "inlier_ratio": round(float(inliers.mean()), 4),
        "residual_m": round(float(np.sqrt(np.mean(residual[inliers] ** 2))), 4),
        "joint_offset_rms_m": round(float(np.sqrt(np.mean(offsets**2))), 4),
        "correspondences": len(residual),
        "joint_residual_m": {n: round(float(r), 4) for n, r in zip(names, rms, strict=True)},
    }


def relative_error(a: RigidTransform, b: RigidTransform) -> tuple[float, float]:
    """(rotation angle in degrees, translation distance in metres) between two poses."""
    angle = math.degrees((a.rotation.inv() * b.rotation).magnitude())
    return angle, float(np.linalg.norm(a.translation - b.translation))
