"""From a BVH skeleton to the 32 Azure Kinect joints, in the simulator's world frame.

World frame: metres, Z up, the floor is ``z = 0`` and x, y lie on it. A BVH file (Y up, the
character facing +Z and its left on +X in the rest pose) is turned by +90° about X::

    world = (x_bvh, -z_bvh, y_bvh)

so the rest-pose character faces -y with its left on +x (right-handed either way).

Most Azure joints are weighted sums of BVH joints (one ``(32, J_bvh)`` weight matrix per file,
built once from the rest pose), so mapping a whole clip is one matrix product. Joint names are
matched by role with aliases so that the CMU files, the Xsens MVN export and the common
"LeftUpLeg/LeftArm" naming all work.

==================  ===========================================================================
Azure joint         from the BVH
==================  ===========================================================================
Hip, Knee,          the joint of that role on each side: ``LeftHip``, ``LeftKnee``,
Shoulder, Elbow,    ``LeftShoulder``, ``LeftElbow``, ``LeftWrist`` (CMU, Xsens) or ``LeftUpLeg``,
Wrist               ``LeftLeg``, ``LeftArm``, ``LeftForeArm``, ``LeftHand``
Ankle               ``LeftAnkle`` or ``LeftFoot``
Foot                ``LeftToe`` or ``LeftToeBase`` (ball of the foot)
Pelvis              midpoint of the two hips (the Kinect pelvis sits between the hip joints)
Neck, Head          the BVH ``Neck`` and ``Head`` joints
SpineNaval,         points at 0.33 and 0.60 of the spine polyline pelvis → root → spine
SpineChest          joints → neck, by rest-pose arc length (they bend with the spine)
Clavicle            0.8 × Neck + 0.2 × Shoulder
Hand, HandTip       wrist + 0.095 m and 0.19 m along the wrist → finger-end direction (wrist
                    rotation × rest direction), scaled by arm length / 0.51 m
Thumb               wrist + wrist rotation × (0.09 m along the hand + 0.09 m forward in the rest
                    pose), same scale
Nose, Eye, Ear      Head + head rotation × offsets (left, up, forward) in metres: nose
                    (0, 0.113, 0.112), eyes (±0.026, 0.12, 0.066), ears (±0.083, 0.057, −0.026)
==================  ===========================================================================

The fractions and offsets were measured on the real Azure Kinect stream of
``unipd_bpe_sample`` (median over 355 frames, in a pelvis/neck/hip body frame for the torso and
a neck/head/ear frame for the face): Kinect pelvis → SpineNaval 0.176 m, → SpineChest 0.318 m,
→ Neck 0.532 m, → Head 0.611 m; the same subject's Xsens neck and head joints are 0.561 m and
0.647 m above the pelvis, the CMU subject's 0.41 m and 0.50 m (a smaller skeleton).
"""

from __future__ import annotations

import numpy as np

from hiros_core.errors import RecordingError
from hiros_core.layouts import AZURE_KINECT
from hiros_sim.bvh import BvhMotion

__all__ = ["BVH_TO_WORLD", "map_to_azure", "mapping_weights"]

BVH_TO_WORLD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""Rotation taking BVH axes (Y up) to the world frame (Z up): ``world = BVH_TO_WORLD @ bvh``."""

_SPINE_FRACTIONS = {"SpineNaval": 0.33, "SpineChest": 0.60}
_CLAVICLE_TO_SHOULDER = 0.2
_HAND, _HAND_TIP, _ARM_REFERENCE = 0.095, 0.19, 0.51
_THUMB_ALONG, _THUMB_FORWARD = 0.09, 0.09
# Offsets from the Azure Head joint in the head's rest frame (x left, y up, z forward), metres.
_FACE = {
    "Nose": (0.0, 0.113, 0.112),
    "EyeLeft": (0.026, 0.12, 0.066),
    "EyeRight": (-0.026, 0.12, 0.066),
    "EarLeft": (0.083, 0.057, -0.026),
    "EarRight": (-0.083, 0.057, -0.026),
}

# The last alias of each role is Bandai-Namco's suffix naming ("UpperLeg_L", "Shoulder_L" being
# the collar bone there too).
_ALIASES = {
    "Hip": ("{s}Hip", "{s}UpLeg", "{s}Thigh", "{c}Hip", "UpperLeg_{c}"),
    "Knee": ("{s}Knee", "{s}Leg", "{s}Shin", "{c}Knee", "LowerLeg_{c}"),
    "Ankle": ("{s}Ankle", "{s}Foot", "{c}Ankle", "Foot_{c}"),
    "Foot": ("{s}Toe", "{s}ToeBase", "{s}Toes", "{c}Toe", "Toes_{c}"),
    # "LeftArm" first: in files that have it, "LeftShoulder" names the collar bone.
    "Shoulder": ("{s}Arm", "{s}UpperArm", "{s}Shoulder", "{c}Shoulder", "UpperArm_{c}"),
    "Elbow": ("{s}Elbow", "{s}ForeArm", "{s}LowerArm", "{c}Elbow", "LowerArm_{c}"),
    "Wrist": ("{s}Wrist", "{s}Hand", "{c}Wrist", "Hand_{c}"),
}
_UNITS = (1.0, 0.01, 0.001, 0.0254)
"""Metres per file unit that a BVH file may use: m, cm, mm, inch."""
_LEG_LENGTH = 0.85
"""A typical adult's hip -> knee -> ankle length, metres (tells the file's unit)."""


def _find(names: tuple[str, ...], candidates: tuple[str, ...], what: str, source: str) -> int:
    lower = {n.lower(): i for i, n in enumerate(names)}
    for candidate in candidates:
        if candidate.lower() in lower:
            return lower[candidate.lower()]
    msg = f"BVH clip {source}: no joint for {what} (tried {', '.join(candidates)})"
    raise RecordingError(msg)


def _rest_positions(motion: BvhMotion) -> np.ndarray:
    """``(J, 3)`` joint positions in the rest pose (all rotations zero)."""
    rest = np.zeros_like(motion.offsets)
    for j, parent in enumerate(motion.parents):
        rest[j] = motion.offsets[j] + (rest[parent] if parent >= 0 else 0.0)
    return rest


def _ancestors(parents: np.ndarray, joint: int) -> list[int]:
    chain = []
    while joint >= 0:
        chain.append(joint)
        joint = int(parents[joint])
    return chain[::-1]


class _Roles:
    """Indices of the BVH joints that play each role, found once per skeleton.

    Also the file's unit (``metres_per_unit``, from the leg length) and, per joint, the rotation
    from the body's rest frame (x left, y up, z forward) to the joint's own frame
    (``rest_frame``): the identity when the rest pose stands upright facing +Z (CMU, Xsens);
    otherwise (Bandai-Namco's rest pose lays every bone along its joint's local x) the one that
    makes the joint's frame in the clip's first frame match the body's frame there.
    """

    def __init__(self, motion: BvhMotion) -> None:
        names, src = motion.joint_names, motion.name
        self.side: dict[str, dict[str, int]] = {}
        for side, short in (("Left", "L"), ("Right", "R")):
            self.side[side] = {
                role: _find(
                    names, tuple(a.format(s=side, c=short) for a in aliases), f"{side}{role}", src
                )
                for role, aliases in _ALIASES.items()
            }
        self.head = _find(names, ("Head",), "Head", src)
        self.neck = _find(names, ("Neck", "Neck1", "LowerNeck"), "Neck", src)
        rest = _rest_positions(motion)
        self.finger_end: dict[str, int] = {}
        self.thumb_end: dict[str, int | None] = {}
        for side in ("Left", "Right"):
            wrist = self.side[side]["Wrist"]
            below = [j for j in range(len(names)) if wrist in _ancestors(motion.parents, j)[:-1]]
            thumbs = [j for j in below if "thumb" in names[j].lower()]
            fingers = [j for j in below if j not in thumbs] or [wrist]
            reach = np.linalg.norm(rest[fingers] - rest[wrist], axis=1)
            self.finger_end[side] = fingers[int(np.argmax(reach))]
            self.thumb_end[side] = thumbs[-1] if thumbs else None
        left, right = self.side["Left"], self.side["Right"]
        leg = np.linalg.norm(rest[left["Knee"]] - rest[left["Hip"]]) + np.linalg.norm(
            rest[left["Ankle"]] - rest[left["Knee"]]
        )
        self.metres_per_unit = min(_UNITS, key=lambda unit: abs(np.log(leg * unit / _LEG_LENGTH)))
        # the spine starts where the two legs branch off (below it may hang a floor-level root)
        hips = (_ancestors(motion.parents, left["Hip"]), _ancestors(motion.parents, right["Hip"]))
        shared = [a for a, b in zip(*hips, strict=False) if a == b]
        self.spine_base = shared[-1] if shared else 0
        self.rest_frame = self._rest_frames(motion, rest)

    def _rest_frames(self, motion: BvhMotion, rest: np.ndarray) -> np.ndarray:
        """``(J, 3, 3)`` rotation from the body's rest frame to each joint's frame."""
        n_joints = len(motion.joint_names)
        hip_left, hip_right = self.side["Left"]["Hip"], self.side["Right"]["Hip"]
        pelvis = 0.5 * (rest[hip_left] + rest[hip_right])
        up = rest[self.neck] - pelvis
        if up[1] > 0.9 * np.linalg.norm(up):  # upright rest pose, Y up
            return np.broadcast_to(np.eye(3), (n_joints, 3, 3))
        first = motion.positions[0]
        left = first[hip_left] - first[hip_right]
        left = np.array([left[0], 0.0, left[2]]) / np.hypot(left[0], left[2])
        body = np.column_stack([left, [0.0, 1.0, 0.0], np.cross(left, [0.0, 1.0, 0.0])])
        return np.einsum("jba,bc->jac", motion.rotations[0], body)  # R_j(0)^T @ body


def mapping_weights(motion: BvhMotion) -> np.ndarray:
    """``(32, J_bvh)`` weights: the linear part of the mapping (``azure = W @ bvh``).

    Hand, hand tip, thumb and face joints get zero rows here; ``map_to_azure`` adds them
    from joint rotations.
    """
    roles = _Roles(motion)
    rest = _rest_positions(motion)
    weights = np.zeros((AZURE_KINECT.n_joints, len(motion.joint_names)))
    idx = AZURE_KINECT.index
    for side in ("Left", "Right"):
        for role, joint in roles.side[side].items():
            weights[idx(f"{role}{side}"), joint] = 1.0
    pelvis = np.zeros(len(motion.joint_names))
    pelvis[[roles.side["Left"]["Hip"], roles.side["Right"]["Hip"]]] = 0.5
    weights[idx("Pelvis")] = pelvis

    weights[idx("Neck"), roles.neck] = 1.0
    weights[idx("Head"), roles.head] = 1.0
    # SpineNaval and SpineChest: fractions of the spine polyline pelvis -> root -> ... -> neck,
    # by rest-pose arc length, so that a bending spine bends them too.
    chain_rows = [pelvis]
    spine = _ancestors(motion.parents, roles.neck)
    for joint in spine[spine.index(roles.spine_base) :]:
        row = np.zeros(len(motion.joint_names))
        row[joint] = 1.0
        chain_rows.append(row)
    chain = np.stack(chain_rows)
    points = chain @ rest
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    for name, fraction in _SPINE_FRACTIONS.items():
        target = fraction * arc[-1]
        k = int(np.clip(np.searchsorted(arc, target, side="right") - 1, 0, len(arc) - 2))
        span = arc[k + 1] - arc[k]
        u = 0.0 if span <= 0 else (target - arc[k]) / span
        weights[idx(name)] = (1.0 - u) * chain[k] + u * chain[k + 1]
    for side in ("Left", "Right"):
        weights[idx(f"Clavicle{side}")] = (1.0 - _CLAVICLE_TO_SHOULDER) * weights[
            idx("Neck")
        ] + _CLAVICLE_TO_SHOULDER * weights[idx(f"Shoulder{side}")]
    return weights


def map_to_azure(motion: BvhMotion) -> np.ndarray:
    """``(T, 32, 3)`` Azure Kinect joints of every frame, world frame (Z up), metres."""
    roles = _Roles(motion)
    rest = _rest_positions(motion) * roles.metres_per_unit
    weights = mapping_weights(motion)
    bvh = motion.positions * roles.metres_per_unit  # (T, Jb, 3), BVH axes, metres
    out = np.einsum("aj,tjc->tac", weights, bvh)
    idx = AZURE_KINECT.index
    for side in ("Left", "Right"):
        s = roles.side[side]
        wrist_rest = rest[s["Wrist"]]
        arm = np.linalg.norm(rest[s["Elbow"]] - rest[s["Shoulder"]]) + np.linalg.norm(
            wrist_rest - rest[s["Elbow"]]
        )
        scale = arm / _ARM_REFERENCE
        wrist = bvh[:, s["Wrist"]]
        end = roles.finger_end[side]
        along_rest = rest[end] - wrist_rest
        if np.linalg.norm(along_rest) < 1e-6:  # no hand in the file: continue the forearm
            along_rest = wrist_rest - rest[s["Elbow"]]
        along_rest = along_rest / np.linalg.norm(along_rest)
        wrist_rot = motion.rotations[:, s["Wrist"]]
        along = np.einsum("tab,b->ta", wrist_rot, along_rest)
        out[:, idx(f"Hand{side}")] = wrist + _HAND * scale * along
        out[:, idx(f"HandTip{side}")] = wrist + _HAND_TIP * scale * along
        forward = roles.rest_frame[s["Wrist"]] @ np.array([0.0, 0.0, 1.0])
        thumb_rest = _THUMB_ALONG * along_rest + _THUMB_FORWARD * forward
        out[:, idx(f"Thumb{side}")] = wrist + scale * np.einsum("tab,b->ta", wrist_rot, thumb_rest)
    head_rot = motion.rotations[:, roles.head] @ roles.rest_frame[roles.head]
    face = np.array(list(_FACE.values()))  # (5, 3) rest frame: x left, y up, z forward
    face_ids = [idx(n) for n in _FACE]
    out[:, face_ids] = out[:, idx("Head")][:, None] + np.einsum("tab,fb->tfa", head_rot, face)
    return out @ BVH_TO_WORLD.T
