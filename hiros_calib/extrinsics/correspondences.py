"""Which tracks are the same person, and their same-instant joint pairs.

Body tracks overlapping in (corrected) time are paired when their pose signatures agree in
metres: the same person has the same limb lengths and the same pose at the same instant,
another person does not. Each track pairs with at most one track of the other camera at a
time (greedy on the mismatch). For every frame of camera a the joints of camera b are
interpolated at the same reference instant; joints a camera sees badly (low confidence,
missing) get weight 0 and are left out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hiros_calib.extrinsics.params import (
    ASSOCIATION_FRAMES,
    MAX_INTERPOLATION_GAP,
    MAX_SIGNATURE_MISMATCH,
    MIN_COMMON_TIME,
    ExtrinsicsParams,
)
from hiros_calib.signature import pose_signature, select_joints
from hiros_calib.sync import CameraClock
from hiros_calib.tracks import BodyTrack
from hiros_core.layouts import Layout

__all__ = ["Correspondences", "associate", "joint_tables", "pair_correspondences", "subsample"]


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


def joint_tables(layout: Layout, names: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    joints, mirror, groups = joint_tables(track_a.layout, params.pose_joints)
    t_b = clock_b.from_reference(clock_a.to_reference(track_a.times))
    positions_b, weights_b = track_b.at(np.asarray(t_b), MAX_INTERPOLATION_GAP)
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
            if len(common) < 10 or t_b[common[-1]] - t_b[common[0]] < MIN_COMMON_TIME:
                continue
            start, end = float(t_b[common[0]]), float(t_b[common[-1]])
            # a median over a few hundred instants tells people apart as well as all of them
            common = common[subsample(len(common), ASSOCIATION_FRAMES)]
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
            if mismatch <= MAX_SIGNATURE_MISMATCH:
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
    positions, weights = track.at(times, MAX_INTERPOLATION_GAP)
    return times, positions, weights


def subsample(count: int, limit: int) -> np.ndarray:
    """At most ``limit`` indices of ``count`` items, evenly spread, first and last included."""
    if count <= limit:
        return np.arange(count)
    return np.linspace(0, count - 1, limit).round().astype(np.int64)
