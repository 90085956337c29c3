"""What a body-tracking SDK gets wrong: occlusion, coherent joint noise, flips, swaps.

All functions work on whole streams at once: ``(P, N, 32, 3)`` positions of P people over the
N frames of one camera, in that camera's frame (metres, z = depth).

Joint noise model (figures fitted by ``hiros_sim.fit``; see that module and ``SimParams``).
The Azure Kinect Body Tracking SDK fits one body model per frame, so its errors are coherent
along the skeleton, not independent per joint: on the real take every limb's length varies by
the same 3.5 % (one whole-body scale per frame; only the thumbs vary more) and a joint's error
correlates with its parent's (0.5-0.7). The simulator therefore makes the SDK's *evidence*
first and then fits a rigid model to it (``fit_body_model``):

1. evidence = truth + noise + a per camera, person and joint bias (``joint_bias``; fixed, or
   drifting as an AR(1) process with time constant ``bias_drift_time``; along the world's up
   the left and right ankle and foot share a smaller one, ``foot_height_bias``), with
   per-joint sigma per axis::

       sigma = (noise_base + noise_per_metre * depth) * (1 + oblique_gain * obliqueness)
               * (occluded_gain if occluded) * (out_of_view_gain if outside the field of view)
               * (extremity_gain on hands, feet and face)

   the depth (z) axis scaled by ``depth_axis_gain``, correlated over time as an AR(1) process
   with correlation time ``noise_correlation_time``; a share ``noise_body_share`` of its
   variance is one shift of the whole body, the rest is the joint's own. ``obliqueness`` is
   ``|sin|`` of the angle between the body's facing direction and the direction to the camera
   (0 seen from the front or back, 1 from the side);
2. the model, with the true limb lengths (the thumbs' jittered by ``thumb_length_cv``), is posed
   root outward on the evidence: each joint at its limb's length from its posed parent, towards
   its own evidence. A joint's error is then its parent's error along the limb plus its own
   across it, about as large as the evidence error at any depth in the tree;
3. the posed model is scaled about its centroid by ``1 + body_scale_cv * AR(1)`` (the SDK's
   per-frame body size), which moves the limb lengths all together;
4. optionally ``noise_residual``: independent noise on top, times the joint's occlusion, view
   and extremity factors (none on the take).

Per-joint error statistics stay about those of the independent model it replaces (the fitted
sigma, bias and correlation time); the limb lengths vary like the real SDK's (median CV 3.8 %
against 3.5 % in the take's situation, was 27 %; ``hiros simulate --fit-noise`` compares).
Hidden and out-of-view joints keep their larger evidence noise; the fit turns it into larger
errors of their limbs' directions, not of their lengths (the take's hidden ankles keep 3.5 %).

Self-occlusion: a joint is hidden when the ray from the camera to it passes through a body part
whose centre is at least 3 cm nearer the camera; bodies are approximated by five spheres along
the pelvis → neck axis (radius 0.15 m) and one head sphere (0.10 m, 7 cm above the Head joint),
which hides the face from behind and the far ear from the side. Other people's spheres occlude
too.

Confidence levels follow the Azure Kinect Body Tracking SDK (``k4abt_joint_confidence_level_t``):
0 NONE (outside the field of view), 1 LOW (occluded, predicted), 2 MEDIUM (seen). They become
the model's confidence through ``CONFIDENCE_OF_LEVEL`` = level / 3 (0, 1/3, 2/3; level 3 HIGH,
which the SDK reserves, would be 1.0), the same convention as ``hiros_azure_bridge`` so that
levels survive the trip through the driver's MarkerArray.
"""

from __future__ import annotations

import numpy as np

from hiros_core.layouts import AZURE_KINECT

__all__ = [
    "CONFIDENCE_OF_LEVEL",
    "LEVEL_LOW",
    "LEVEL_MEDIUM",
    "LEVEL_NONE",
    "ar1_noise",
    "fit_body_model",
    "flip_front_back",
    "in_view",
    "occluded",
    "plant_legs",
    "planted_feet",
]

LEVEL_NONE, LEVEL_LOW, LEVEL_MEDIUM = 0, 1, 2
CONFIDENCE_OF_LEVEL = np.arange(4) / 3.0
"""Model confidence of each SDK level: NONE, LOW, MEDIUM, HIGH."""

_IDX = AZURE_KINECT.index
_TORSO_RADIUS, _HEAD_RADIUS = 0.15, 0.10
_IN_FRONT = 0.03
"""A sphere occludes a joint only if its centre is this much (m) nearer the camera."""
_TORSO_SPHERES = np.linspace(0.0, 1.0, 5)
_MIDLINE = np.array(
    [_IDX(n) for n in ("Pelvis", "SpineNaval", "SpineChest", "Neck", "Head")], dtype=np.int64
)
_LEFT_RIGHT_LEGS = np.arange(AZURE_KINECT.n_joints)
for _side, _other in (("Left", "Right"), ("Right", "Left")):
    for _part in ("Hip", "Knee", "Ankle", "Foot"):
        _LEFT_RIGHT_LEGS[_IDX(f"{_part}{_side}")] = _IDX(f"{_part}{_other}")
LEGS_SWAP = _LEFT_RIGHT_LEGS
"""Permutation swapping only the legs (the SDK's most common left/right confusion)."""
LEGS = tuple(
    tuple(_IDX(f"{part}{side}") for part in ("Hip", "Knee", "Ankle", "Foot"))
    for side in ("Left", "Right")
)
"""Hip, knee, ankle and foot joints of the left and the right leg."""
PLANTED_SPEED = 0.3
"""A foot slower than this (m/s) is planted: twice the floor fit's ``RESTING_SPEED``, so that
the frames the fit takes as resting on the SDK's noisy speeds, just before and after the true
foot rests, are planted too (at the fit's own speed, the foot rests 0.2 cm higher on walks)."""


def in_view(
    positions: np.ndarray, fov_deg: tuple[float, float], depth_range: tuple[float, float]
) -> np.ndarray:
    """``(...,)`` True where points ``(..., 3)`` (camera frame) are inside the view frustum."""
    x, y, z = positions[..., 0], positions[..., 1], positions[..., 2]
    half_w, half_h = np.tan(np.deg2rad(fov_deg[0]) / 2), np.tan(np.deg2rad(fov_deg[1]) / 2)
    with np.errstate(invalid="ignore"):
        return (
            (z > depth_range[0])
            & (z < depth_range[1])
            & (np.abs(x) < half_w * z)
            & (np.abs(y) < half_h * z)
        )


def _spheres(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sphere centres ``(P, N, S, 3)`` and radii ``(S,)`` approximating each body."""
    pelvis = positions[:, :, _IDX("Pelvis")]
    neck = positions[:, :, _IDX("Neck")]
    torso = pelvis[:, :, None] + _TORSO_SPHERES[None, None, :, None] * (neck - pelvis)[:, :, None]
    head = positions[:, :, _IDX("Head")] + 0.07 * (neck - pelvis) / np.linalg.norm(
        neck - pelvis, axis=-1, keepdims=True
    )
    centres = np.concatenate([torso, head[:, :, None]], axis=2)
    radii = np.concatenate([np.full(_TORSO_SPHERES.size, _TORSO_RADIUS), [_HEAD_RADIUS]])
    return centres, radii


def occluded(positions: np.ndarray) -> np.ndarray:
    """``(P, N, 32)`` True where a joint is hidden from the camera at the origin.

    Args:
        positions: ``(P, N, 32, 3)`` camera frame, NaN for absent people.

    """
    centres, radii = _spheres(positions)  # (P, N, S, 3)
    hidden = np.zeros(positions.shape[:3], dtype=bool)
    length2 = np.einsum("pnjc,pnjc->pnj", positions, positions)[..., None]  # (P, N, J, 1)
    length = np.sqrt(length2)
    for occluder in range(positions.shape[0]):  # a few people: loop over occluders only
        c = centres[occluder]  # (N, S, 3)
        along = np.einsum("pnjc,nsc->pnjs", positions, c)  # ray · centre
        centre2 = np.einsum("nsc,nsc->ns", c, c)[None, :, None, :]
        with np.errstate(invalid="ignore", divide="ignore"):
            # squared distance from the sphere centre to the ray's line, and where along it
            dist2 = centre2 - along * along / length2
            s = along / length2
            blocked = (dist2 < radii * radii) & (s > 0) & (s * length < length - _IN_FRONT)
        blocked = blocked.any(axis=-1)
        blocked[occluder][:, _MIDLINE] = False  # the spine is inside its own torso spheres
        hidden |= blocked
    return hidden


def ar1_noise(rng: np.random.Generator, shape: tuple[int, ...], rho: float) -> np.ndarray:
    """Unit-variance AR(1) noise correlated along axis 1 (frames) with coefficient ``rho``."""
    white = rng.standard_normal(shape)
    if rho <= 0.0:
        return white
    scale = np.sqrt(1.0 - rho * rho)
    white[:, 0] /= scale  # start in the stationary distribution, not at zero
    # imported here: scipy.signal takes most of a second to import, and every ``hiros`` command
    # imports this package to list the simulator's presets in its help
    from scipy.signal import lfilter

    return lfilter([scale], [1.0, -rho], white, axis=1)


_LEFT_FEET = np.array([_IDX("AnkleLeft"), _IDX("FootLeft")])
_FEET = np.concatenate([_LEFT_FEET, [_IDX("AnkleRight"), _IDX("FootRight")]])


def level_feet_bias(bias: np.ndarray, up: np.ndarray, height_share: float) -> None:
    """Give both ankles and both feet the left's offset along ``up`` times ``height_share``.

    ``bias`` is ``(P, N or 1, 32, 3)`` joint offsets in a camera's frame, changed in place;
    ``up`` is the world's up in that frame. The real SDKs misplace a person's two feet in
    height alike, and far less than their other joints: a resting foot is seen against the
    floor (docs/world-frame.md). The left joints' draws are reused, scaled, so that no other
    draw of the simulation moves. Offsets across the up stay each joint's own.
    """
    height = (bias[..., _LEFT_FEET, :] @ up) * height_share
    height = np.concatenate([height, height], axis=-1)
    bias[..., _FEET, :] += (height - bias[..., _FEET, :] @ up)[..., None] * up


def flip_front_back(positions: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """The skeleton an SDK fits when it takes a person's back for their front.

    Reflect the joints through the body's frontal plane (the plane through the pelvis whose
    normal is the facing direction) and exchange left and right labels: the result faces the
    camera with its anatomical sides where a front-facing body would have them.

    Args:
        positions: ``(M, 32, 3)``.
        forward: ``(M, 3)`` unit facing directions in the same frame.

    """
    pelvis = positions[:, _IDX("Pelvis")][:, None]
    depth = np.einsum("mjc,mc->mj", positions - pelvis, forward)
    reflected = positions - 2.0 * depth[..., None] * forward[:, None]
    return reflected[:, AZURE_KINECT.mirror]


def _tree_levels() -> list[np.ndarray]:
    """Non-root joints grouped by depth in the Azure tree, root outward."""
    parents = np.asarray(AZURE_KINECT.parents)
    depth = np.zeros(AZURE_KINECT.n_joints, dtype=np.int64)
    for joint in range(1, AZURE_KINECT.n_joints):  # parents come before children in k4abt order
        depth[joint] = depth[parents[joint]] + 1
    return [np.flatnonzero(depth == level) for level in range(1, depth.max() + 1)]


_PARENTS = np.asarray(AZURE_KINECT.parents)
_LEVELS = _tree_levels()


def fit_body_model(
    evidence: np.ndarray, truth: np.ndarray, scale: np.ndarray, length_gain: np.ndarray
) -> np.ndarray:
    """The skeleton an SDK reports when it fits one rigid body model per frame to noisy evidence.

    The model has the person's true limb lengths (times ``length_gain``) and is posed root
    outward: the root sits on its evidence and each joint lies on the sphere of its limb's
    length around its already posed parent, at the point nearest its own evidence (one
    forward pass of FABRIK, Aristidou & Lasenby 2011). The whole model is then scaled by
    ``scale`` about its centroid (the SDK's per-frame estimate of body size).

    Errors therefore follow the skeleton: a joint's error is its parent's error along the limb
    plus its own evidence error across it, so it neither grows with the depth in the tree nor
    is independent of the parent's, and limb lengths vary only with the scale (and
    ``length_gain``), as on the real Azure Kinect take (``hiros_sim.fit``).

    Args:
        evidence: ``(..., 32, 3)`` noisy joints.
        truth: ``(..., 32, 3)`` true joints (the limb lengths).
        scale: ``(...)`` whole-body scale, 1 = true size.
        length_gain: ``(..., 32)`` factor on each link's length, by link id (child joint).

    """
    lengths = np.linalg.norm(truth - truth[..., np.maximum(_PARENTS, 0), :], axis=-1)
    lengths = lengths * length_gain
    posed = evidence.copy()
    for joints in _LEVELS:  # a handful of levels; each one vectorised over joints and frames
        parents = _PARENTS[joints]
        toward = evidence[..., joints, :] - posed[..., parents, :]
        norm = np.linalg.norm(toward, axis=-1, keepdims=True)
        # evidence on the parent itself: keep the true limb direction
        limb = truth[..., joints, :] - truth[..., parents, :]
        with np.errstate(invalid="ignore", divide="ignore"):
            direction = np.where(
                norm > 1e-9, toward / norm, limb / np.linalg.norm(limb, axis=-1, keepdims=True)
            )
        posed[..., joints, :] = posed[..., parents, :] + lengths[..., joints, None] * direction
    centre = posed.mean(axis=-2, keepdims=True)
    return centre + np.asarray(scale)[..., None, None] * (posed - centre)


def planted_feet(positions: np.ndarray, rate: float) -> np.ndarray:
    """``(P, N, 2)`` True where the left and the right foot of true ``(P, N, 32, 3)`` joints rest.

    A foot is planted where its joint moves slower than :data:`PLANTED_SPEED` over the floor
    fit's ``SPEED_BASELINE`` (``hiros_calib.world``); the first and last half baseline and
    absent frames (NaN) count as moving.
    """
    # imported here: hiros_calib takes a quarter of a second to import, and every ``hiros``
    # command imports this package to list the simulator's presets in its help
    from hiros_calib.world import speed_over_baseline

    times = np.arange(positions.shape[1]) / rate
    feet = [leg[3] for leg in LEGS]
    speed = np.stack([speed_over_baseline(person[:, feet], times) for person in positions])
    return speed < PLANTED_SPEED  # NaN never rests


def _unit(vectors: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return vectors / np.maximum(norm, 1e-9)


def plant_legs(
    fitted: np.ndarray,
    evidence: np.ndarray,
    truth: np.ndarray,
    scale: np.ndarray,
    planted: np.ndarray,
) -> np.ndarray:
    """The fitted skeletons with each planted foot on its own evidence: the legs give.

    The rigid model posed root outward (:func:`fit_body_model`) puts a foot at the end of its
    leg, so the foot carries the pelvis's, hip's and knee's errors and, since a noisy limb
    direction shortens the leg's vertical reach, rests too high. The real SDK keeps a planted
    foot where it is while the pelvis moves (docs/world-frame.md). So, where a foot is
    planted, the leg is posed again from its fitted hip towards the foot's evidence:

    1. the ankle's target is at the foot link's length from the foot's evidence, towards the
       ankle's evidence;
    2. where that target is beyond the leg's reach (the hip too high above it), the heel
       rises: the ankle turns about the foot's evidence towards the hip (:func:`_within_reach`);
    3. the knee bends so that thigh and shank reach the target (two-bone inverse kinematics,
       the knee on the side of the rigid fit's knee), or the straight leg points at it;
    4. the foot goes at its link's length from the ankle, towards its evidence: on it, but
       where even a raised heel cannot reach (a little above it).

    Every link keeps its length (the true one times ``scale``), as the real SDK's limbs keep
    their ratios; the rest of the body is left as fitted.

    Args:
        fitted: ``(P, N, 32, 3)`` :func:`fit_body_model`'s skeletons.
        evidence: ``(P, N, 32, 3)`` the noisy joints they were fitted to.
        truth: ``(P, N, 32, 3)`` true joints (the limb lengths).
        scale: ``(P, N)`` the fit's whole-body scale.
        planted: ``(P, N, 2)`` where the left and right foot rest (:func:`planted_feet`).

    """
    lengths = np.linalg.norm(truth - truth[..., np.maximum(_PARENTS, 0), :], axis=-1)
    lengths = lengths * scale[..., None]
    placed = fitted.copy()
    for side, (hip, knee, ankle, foot) in enumerate(LEGS):
        legs = _bent_leg(placed, evidence, lengths, (hip, knee, ankle, foot))
        for joint, position in zip((knee, ankle, foot), legs, strict=True):
            placed[..., joint, :] = np.where(
                planted[..., side, None], position, placed[..., joint, :]
            )
    return placed


def _bent_leg(
    placed: np.ndarray, evidence: np.ndarray, lengths: np.ndarray, leg: tuple[int, int, int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Knee, ankle and foot of a leg from its placed hip towards its foot's evidence."""
    hip, knee, ankle, foot = leg
    thigh, shank, link = lengths[..., knee], lengths[..., ankle], lengths[..., foot, None]
    foot_seen = evidence[..., foot, :]
    target = foot_seen + link * _unit(evidence[..., ankle, :] - foot_seen)
    start = placed[..., hip, :]
    target = _within_reach(target, start, thigh + shank, foot_seen, link[..., 0])
    along = _unit(target - start)
    distance = np.clip(
        np.linalg.norm(target - start, axis=-1), np.abs(thigh - shank) + 1e-6, thigh + shank
    )
    bend = placed[..., knee, :] - start
    side = _unit(bend - np.einsum("...c,...c", bend, along)[..., None] * along)
    cos = np.clip((thigh**2 + distance**2 - shank**2) / (2.0 * thigh * distance), -1.0, 1.0)
    knee_at = start + thigh[..., None] * (
        cos[..., None] * along + np.sqrt(1.0 - cos * cos)[..., None] * side
    )
    ankle_at = knee_at + shank[..., None] * _unit(target - knee_at)
    return knee_at, ankle_at, ankle_at + link * _unit(foot_seen - ankle_at)


def _within_reach(
    target: np.ndarray, hip: np.ndarray, reach: np.ndarray, foot: np.ndarray, link: np.ndarray
) -> np.ndarray:
    """The ankle's target, or where it is out of the leg's reach, the heel raised.

    The ankle then turns about the foot up towards the hip: the point at the leg's reach
    from the hip and the link's length from the foot nearest the target. Where even that is
    out of reach, the target stays (the straight leg's foot stops short of its evidence).
    """
    axis = foot - hip
    distance = np.linalg.norm(axis, axis=-1)
    axis = _unit(axis)
    # the circle where the two spheres meet: its centre along the axis, its radius
    along = (distance**2 + reach**2 - link**2) / (2.0 * np.maximum(distance, 1e-9))
    radius = np.sqrt(np.maximum(reach**2 - along**2, 0.0))
    offset = target - hip
    across = _unit(offset - np.einsum("...c,...c", offset, axis)[..., None] * axis)
    raised = hip + along[..., None] * axis + radius[..., None] * across
    beyond = np.linalg.norm(offset, axis=-1) > reach
    meets = distance <= reach + link
    return np.where((beyond & meets)[..., None], raised, target)
