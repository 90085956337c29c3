"""All camera poses at once from every pair's correspondences, reference fixed, so loops close."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hiros_calib.extrinsics.correspondences import subsample
from hiros_calib.extrinsics.halves import relative_error, second_half
from hiros_calib.extrinsics.pair_pose import PairPose
from hiros_calib.extrinsics.params import (
    INLIER_SIGMAS,
    INLIER_THRESHOLD,
    JOINT_OFFSET_ROUNDS,
    LOSS,
    MAX_CORRESPONDENCES,
    MIN_CORRESPONDENCES,
    OFFSET_SHRINKAGE,
)
from hiros_calib.extrinsics.robust import Terms, flatten_pairs, loss_weights, robust_solve
from hiros_core.geometry import RigidTransform

__all__ = ["CameraPose", "solve_poses"]


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

    def terms(self, rows: np.ndarray | None = None) -> Terms:
        """The block (or its ``rows``) as terms of :func:`robust_solve`, offsets as they are."""
        rows = slice(None) if rows is None else rows
        return Terms(
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
        weight = self.weights * loss_weights(norm2, loss)
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
) -> dict[str, CameraPose]:
    """All camera poses at once from every pair's joint correspondences.

    Minimises ``sum rho(|T_a p_a - T_b p_b - d|^2)`` over every camera pair's correspondences
    (weights applied, reference camera fixed at the identity), starting from the poses
    chained along the most reliable pairs. ``d`` are per (person, joint) offsets, estimated
    alternately with the poses (``JOINT_OFFSET_ROUNDS``): SDKs place a given person's joint a
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
        _block(p)
        for p in pairs
        if p.ok and p.correspondences and p.camera_a in initial and p.camera_b in initial
    ]
    poses = {c: initial[c] for c in cameras if c in initial}
    scale = float(np.median([b.pair.quality["scale_m"] for b in blocks]) if blocks else 0.05)
    if unknown:
        for round_index in range(JOINT_OFFSET_ROUNDS + 1):
            if round_index:
                for block in blocks:
                    block.update_offsets(poses, scale, OFFSET_SHRINKAGE, LOSS)
            poses = robust_solve(
                poses, unknown, [b.terms() for b in blocks], loss=LOSS, scale=scale
            )
    spreads = _split_half_spreads(poses, unknown, blocks, scale)
    for camera, transform in poses.items():
        pose = out[camera]
        pose.status, pose.transform = "ok", transform
        pose.quality = _pose_quality(camera, blocks, poses)
        if camera in spreads:
            pose.quality["pose_split_deg"] = round(spreads[camera][0], 3)
            pose.quality["pose_split_cm"] = round(100 * spreads[camera][1], 2)
    return out


def _split_half_spreads(
    poses: dict[str, RigidTransform],
    unknown: list[str],
    blocks: list[_Block],
    scale: float,
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
            ) >= MIN_CORRESPONDENCES
        }  # fmt: skip
        if not enough:
            return {}
        terms = [b.terms(r) for b, r in zip(blocks, rows, strict=True) if r.any()]
        solved = robust_solve(poses, sorted(enough), terms, loss=LOSS, scale=scale)
        halves.append({c: solved[c] for c in enough})
    return {
        camera: relative_error(halves[0][camera], halves[1][camera])
        for camera in halves[0].keys() & halves[1].keys()
    }


def _block(pair: PairPose) -> _Block:
    c = pair.correspondences
    assert c is not None
    points_a, points_b, w, joint, frame = flatten_pairs(c.points_a, c.points_b, c.weights)
    keep = subsample(len(points_a), MAX_CORRESPONDENCES)
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
    inliers = residual < min(INLIER_THRESHOLD, INLIER_SIGMAS * scale)
    rms = np.sqrt(np.bincount(joint[inliers], residual[inliers] ** 2, len(names))
                  / np.maximum(np.bincount(joint[inliers], None, len(names)), 1))  # fmt: skip
    return {
        "inlier_ratio": round(float(inliers.mean()), 4),
        "residual_m": round(float(np.sqrt(np.mean(residual[inliers] ** 2))), 4),
        "joint_offset_rms_m": round(float(np.sqrt(np.mean(offsets**2))), 4),
        "correspondences": len(residual),
        "joint_residual_m": {n: round(float(r), 4) for n, r in zip(names, rms, strict=True)},
    }
