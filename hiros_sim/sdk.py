"""What one simulated camera's body-tracking SDK reports, as arrays over its frames.

``observe`` moves the truth into the camera (its pose, clock, frame timing, drops and log
times: ``hiros_sim.simulate``'s docstring) and applies the SDK's view and mistakes from
``hiros_sim.noise``: field of view and occlusion confidence levels, missed people, joint noise
fitted to a real Azure Kinect, front/back flips and left/right swaps, body ids that change,
and ghost bodies. ``bumped_pose`` is a camera knocked during the recording.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.calibration import CameraCalibration
from hiros_core.layouts import AZURE_KINECT
from hiros_sim.cameras import camera_to_reference, reference_to_camera
from hiros_sim.noise import (
    LEGS_SWAP,
    LEVEL_LOW,
    LEVEL_MEDIUM,
    LEVEL_NONE,
    ar1_noise,
    fit_body_model,
    flip_front_back,
    in_view,
    level_feet_bias,
    occluded,
    plant_legs,
    planted_feet,
)
from hiros_sim.params import SimParams
from hiros_sim.people import Clip, body_forward

if TYPE_CHECKING:
    from hiros_sim.simulate import Truth

__all__ = ["CameraStream", "bumped_pose", "observe"]

_IDX = AZURE_KINECT.index
_THUMBS = np.array([_IDX("ThumbLeft"), _IDX("ThumbRight")])
_LOWER_LEGS = np.array(
    [_IDX(f"{part}{side}") for side in ("Left", "Right") for part in ("Ankle", "Foot")]
)
"""Ankle and foot joints, left then right: quieter while their foot is planted."""
_EXTREMITIES = np.array(
    [
        _IDX(f"{part}{side}")
        for part in ("Hand", "HandTip", "Thumb", "Ankle", "Foot", "Eye", "Ear")
        for side in ("Left", "Right")
    ]
    + [_IDX("Nose")]
)
"""Hands, feet and face: the joints a noisier SDK gets most wrong (``extremity_gain``)."""


@dataclass
class CameraStream:
    """One camera's observations before they become groups."""

    stamps_ns: np.ndarray  # (N,)
    receive_ns: np.ndarray  # (N,) reference clock
    kept: np.ndarray  # (N,) frame published
    positions: np.ndarray  # (P, N, 32, 3) camera frame, with noise
    levels: np.ndarray  # (P, N, 32) SDK confidence levels
    detected: np.ndarray  # (P, N)
    ids: np.ndarray  # (P, N) SDK body ids
    ghosts: list[tuple[int, int, int, np.ndarray, np.ndarray]]  # start, stop, id, pos, levels


def bumped_pose(cam: CameraCalibration, params: SimParams) -> CameraCalibration:
    """The pose of ``cam`` after ``params``' bump (same clock).

    Turned about the vertical through its position by ``bump_rotation`` degrees, then slid
    ``bump_shift`` m along world x.
    """
    turn = Rotation.from_euler("z", params.bump_rotation, degrees=True)
    rotation = (turn * Rotation.from_quat(cam.rotation)).as_quat()
    translation = np.asarray(cam.translation, float) + np.array([params.bump_shift, 0.0, 0.0])
    return replace(cam, translation=translation, rotation=rotation)


def _in_camera(
    cam: CameraCalibration, world: np.ndarray, forward: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World points ``(P, N, 32, 3)`` and facing directions ``(P, N, 3)`` in ``cam``'s frame."""
    rotation = Rotation.from_quat(cam.rotation).as_matrix()
    return (world - cam.translation) @ rotation, forward @ rotation  # R^T (p - t)


def observe(
    cam: CameraCalibration,
    truth: Truth,
    clips: list[Clip],
    params: SimParams,
    rng: np.random.Generator,
    *,
    host_rng: np.random.Generator,
    bump: CameraCalibration | None = None,
) -> CameraStream:
    """Everything one camera reports, as arrays over its frames.

    ``host_rng`` draws the camera host's log-time latency (``log_clock="camera"``) apart from
    ``rng``, so that the rest of the stream does not depend on the log clock.
    """
    noisy = params.noise
    rate = params.rate
    start_ref = params.clock_start + rng.uniform(0.0, params.start_spread)
    start_ns = round(float(reference_to_camera(cam, np.array(start_ref))) * 1e9)
    n_frames = int((params.duration - params.start_spread - 2.0 / rate) * rate)
    offsets = np.arange(n_frames) / rate
    if noisy and params.jitter > 0:
        offsets = offsets + rng.normal(0.0, params.jitter, n_frames)
    stamps_ns = start_ns + np.round(offsets * 1e9).astype(np.int64)
    kept = rng.random(n_frames) >= params.drop_rate if noisy else np.ones(n_frames, bool)
    t_ref = camera_to_reference(cam, stamps_ns * 1e-9)
    if params.log_clock == "camera":
        latency = host_rng.uniform(*params.host_latency)
        latency = latency + params.host_jitter * np.abs(host_rng.standard_normal(n_frames))
        receive_ns = stamps_ns + np.round(latency * 1e9).astype(np.int64)
    else:
        receive_ns = np.round((t_ref + params.latency) * 1e9).astype(np.int64)

    world = truth.at(t_ref)  # (P, N, 32, 3)
    facing = body_forward(world)  # (P, N, 3) world frame
    positions, forward = _in_camera(cam, world, facing)
    if bump is not None:
        moved = t_ref >= params.clock_start + params.bump_time
        after, forward_after = _in_camera(bump, world, facing)
        positions = np.where(moved[None, :, None, None], after, positions)
        forward = np.where(moved[None, :, None], forward_after, forward)
    present = np.isfinite(world).all(axis=(2, 3))
    joint_in = in_view(positions, params.fov, params.depth_range)
    hidden = occluded(positions)
    levels = np.where(joint_in, np.where(hidden, LEVEL_LOW, LEVEL_MEDIUM), LEVEL_NONE)
    detected = present & (joint_in.mean(axis=-1) >= 0.5)
    if noisy:
        detected &= rng.random(detected.shape) >= params.miss_rate
        up = Rotation.from_quat(cam.rotation).as_matrix()[2]  # the world's z in the camera frame
        positions = _joint_noise(
            positions, forward, joint_in, hidden, up=up, params=params, rng=rng
        )
        _sdk_mistakes(positions, levels, forward, detected, params=params, rng=rng)
    ghosts_spec = []
    if noisy:
        for _ in range(rng.poisson(params.ghost_rate * params.duration / 60.0)):
            first = int(rng.integers(0, n_frames))
            stop = min(n_frames, first + max(1, int(rng.uniform(0.2, 1.5) * rate)))
            ghosts_spec.append((first, stop))
    ids, ghost_ids = _sdk_ids(detected, ghosts_spec, params, rng)
    ghosts = []
    for (first, stop), ghost_id in zip(ghosts_spec, ghost_ids, strict=True):
        pose, ghost_levels = _ghost_pose(cam, clips, rng)
        jitter = rng.normal(0.0, 0.03, (stop - first, *pose.shape))
        ghosts.append((first, stop, ghost_id, pose[None] + jitter, ghost_levels))
    return CameraStream(stamps_ns, receive_ns, kept, positions, levels, detected, ids, ghosts)


def _facing_cos(positions: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """``(P, N)`` cosine between each body's facing and the direction to the camera."""
    pelvis = positions[:, :, _IDX("Pelvis")]
    with np.errstate(invalid="ignore", divide="ignore"):
        to_camera = -pelvis / np.linalg.norm(pelvis, axis=-1, keepdims=True)
        return np.einsum("pnc,pnc->pn", forward, to_camera)


def _joint_noise(
    positions: np.ndarray,
    forward: np.ndarray,
    joint_in: np.ndarray,
    hidden: np.ndarray,
    *,
    up: np.ndarray,
    params: SimParams,
    rng: np.random.Generator,
) -> np.ndarray:
    """What the SDK reports for true ``(P, N, 32, 3)`` positions (model in ``hiros_sim.noise``).

    The evidence is each joint plus correlated noise (part of it one shift of the whole body)
    and a fixed bias, a planted foot's ankle and foot quieter (``planted_gain``); the SDK's
    rigid body model, scaled per frame, is fitted to it, and its legs then bend so that each
    planted foot stays on its evidence.
    """
    obliqueness = np.sqrt(np.clip(1.0 - _facing_cos(positions, forward) ** 2, 0.0, 1.0))
    depth = np.abs(positions[..., 2])
    sigma = (params.noise_base + params.noise_per_metre * depth) * (
        1.0 + params.oblique_gain * obliqueness
    )[..., None]
    gain = np.where(hidden, params.occluded_gain, 1.0)
    gain = gain * np.where(joint_in, 1.0, params.out_of_view_gain)
    if params.extremity_gain != 1.0:
        gain[..., _EXTREMITIES] *= params.extremity_gain
    planted = planted_feet(positions, params.rate)
    gain[..., _LOWER_LEGS] *= np.where(np.repeat(planted, 2, axis=-1), params.planted_gain, 1.0)
    sigma = sigma * gain
    rho = float(np.exp(-1.0 / (params.rate * params.noise_correlation_time)))
    n_people, n_frames, n_joints, _ = positions.shape
    share = params.noise_body_share
    own = ar1_noise(rng, positions.shape, rho)
    body = ar1_noise(rng, (n_people, n_frames, 1, 3), rho)
    error = (np.sqrt(1.0 - share) * own + np.sqrt(share) * body) * sigma[..., None]
    error[..., 2] *= params.depth_axis_gain
    if params.bias_drift_time > 0.0:
        rho_bias = float(np.exp(-1.0 / (params.rate * params.bias_drift_time)))
        bias = params.joint_bias * ar1_noise(rng, positions.shape, rho_bias)
    else:
        bias = rng.normal(0.0, params.joint_bias, (n_people, 1, n_joints, 3))
    if params.joint_bias > 0.0:
        level_feet_bias(bias, up, params.foot_height_bias / params.joint_bias)
    scale = 1.0 + params.body_scale_cv * ar1_noise(rng, (n_people, n_frames), rho)
    length_gain = np.ones((n_people, n_frames, n_joints))
    length_gain[..., _THUMBS] += params.thumb_length_cv * ar1_noise(
        rng, (n_people, n_frames, _THUMBS.size), rho
    )
    evidence = positions + error + bias
    fitted = fit_body_model(evidence, positions, scale, length_gain)
    fitted = plant_legs(fitted, evidence, positions, scale, planted)
    if params.noise_residual > 0.0:
        fitted += params.noise_residual * gain[..., None] * ar1_noise(rng, positions.shape, rho)
    return fitted


def _sdk_mistakes(
    positions: np.ndarray,
    levels: np.ndarray,
    forward: np.ndarray,
    detected: np.ndarray,
    *,
    params: SimParams,
    rng: np.random.Generator,
) -> None:
    """Front/back flips and left/right swaps, in place."""
    n_people, n_frames = detected.shape
    rate = params.rate
    away = detected & (_facing_cos(positions, forward) < params.facing_away_cos)
    episodes = _runs(away)
    flip_episode = rng.random(episodes.max() + 1) < params.flip_probability
    flipped = away & flip_episode[episodes]
    for p in range(n_people):
        for _ in range(rng.poisson(params.flip_rate * params.duration / 60.0)):
            first = int(rng.integers(0, n_frames))
            flipped[p, first : first + int(rng.uniform(0.5, 3.0) * rate)] = True
    flipped &= detected
    if flipped.any():
        positions[flipped] = flip_front_back(positions[flipped], forward[flipped])
        levels[flipped] = levels[flipped][:, AZURE_KINECT.mirror]
    for p in range(n_people):
        for _ in range(rng.poisson(params.swap_rate * params.duration / 60.0)):
            first = rng.integers(0, n_frames)
            stop = min(n_frames, first + int(rng.uniform(0.2, 1.0) * rate))
            perm = LEGS_SWAP if rng.random() < 0.7 else AZURE_KINECT.mirror
            span = slice(first, stop)
            positions[p, span] = positions[p, span][:, perm]
            levels[p, span] = levels[p, span][:, perm]


def _sdk_ids(
    detected: np.ndarray,
    ghosts: list[tuple[int, int]],
    params: SimParams,
    rng: np.random.Generator,
) -> tuple[np.ndarray, list[int]]:
    """``(P, N)`` SDK body ids and each ghost's id.

    Like the SDK, ids count up from 1 in order of appearance; a person gets a new id when seen
    again after ``reid_gap`` seconds and at random changes (``id_change_rate``).
    """
    n_people, n_frames = detected.shape
    new_track = np.zeros_like(detected)
    gap = round(params.reid_gap * params.rate)
    for p in range(n_people):
        seen = np.flatnonzero(detected[p])
        if seen.size:
            new_track[p, seen[np.concatenate([[True], np.diff(seen) > gap])]] = True
        if params.noise:
            count = rng.poisson(params.id_change_rate * params.duration / 60.0)
            changes = rng.integers(0, n_frames, count)
            new_track[p, changes] |= detected[p, changes]
    events = [(int(f), 0, int(p)) for p, f in zip(*np.nonzero(new_track), strict=True)]
    events += [(first, 1, g) for g, (first, _) in enumerate(ghosts)]
    events.sort()
    ids = np.zeros((n_people, n_frames), dtype=np.int64)
    ghost_ids = [0] * len(ghosts)
    for next_id, (first, kind, who) in enumerate(events, start=1):
        if kind == 0:
            ids[who, first] = next_id
        else:
            ghost_ids[who] = next_id
    # each id holds until the person's next new track
    frame = np.arange(n_frames)
    for p in range(n_people):
        last = np.maximum.accumulate(np.where(ids[p] > 0, frame, -1))
        ids[p] = np.where(last >= 0, ids[p][np.maximum(last, 0)], 0)
    return ids, ghost_ids


def _ghost_pose(
    cam: CameraCalibration, clips: list[Clip], rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """A spurious body in the camera frame: a random mocap pose, somewhere in view, distorted."""
    clip = clips[int(rng.integers(len(clips)))]
    pose = clip.positions[int(rng.integers(clip.positions.shape[0]))]
    pose = pose - np.array([*pose[_IDX("Pelvis"), :2], 0.0])
    yaw = rng.uniform(0.0, 2.0 * np.pi)
    c, s = np.cos(yaw), np.sin(yaw)
    pose = pose @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T
    rotation = Rotation.from_quat(cam.rotation).as_matrix()
    ahead = rotation[:, 2].copy()
    ahead[2] = 0.0
    ahead /= np.linalg.norm(ahead)
    right = np.array([-ahead[1], ahead[0], 0.0])
    spot = cam.translation + rng.uniform(1.5, 4.5) * ahead + rng.uniform(-1.0, 1.0) * right
    world = pose + np.array([spot[0], spot[1], 0.0])
    world = world + rng.normal(0.0, 0.05, world.shape)
    positions = (world - cam.translation) @ rotation
    levels = np.where(rng.random(AZURE_KINECT.n_joints) < 0.7, LEVEL_LOW, LEVEL_MEDIUM)
    return positions, levels


def _runs(mask: np.ndarray) -> np.ndarray:
    """``(P, N)`` run label of each True element (0 where False), unique across rows."""
    starts = mask & ~np.concatenate([np.zeros((mask.shape[0], 1), bool), mask[:, :-1]], axis=1)
    labels = np.cumsum(starts.ravel()).reshape(mask.shape)
    return np.where(mask, labels, 0)
