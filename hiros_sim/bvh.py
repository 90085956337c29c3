"""BVH motion capture files: parse the hierarchy and the motion, then forward kinematics.

A BVH file is a joint tree (``OFFSET`` of each joint from its parent in the rest pose, the
``CHANNELS`` each frame carries) followed by one line of channel values per frame. Rotation
channels are Euler angles in degrees applied in the order listed (intrinsic), so a joint with
``Zrotation Yrotation Xrotation`` has the local rotation ``Rz @ Ry @ Rx``. Forward kinematics
gives, for every frame, each joint's global rotation and position::

    R_j = R_parent @ R_local_j
    p_j = p_parent + R_parent @ local_j

where ``local_j`` is the joint's ``OFFSET`` with each axis that has a position channel replaced by
that channel's value: a root's channels place it, and files that give every joint position
channels (Bandai-Namco's, whose channels repeat the offsets) keep their bone lengths.

``End Site`` entries become joints named ``<parent>_End`` (no channels): they carry the head top,
finger and toe tips that the Azure Kinect mapping needs.

The reader keeps the file's own axes and unit (the CMU "scaled" files and the Xsens export are
in metres, Y up, characters facing +Z in the rest pose; Bandai-Namco's are in centimetres with
every bone along its joint's local x); ``hiros_sim.mapping`` converts to the simulator's world
frame and to metres.
"""

from __future__ import annotations

import gzip
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.errors import RecordingError

__all__ = ["BvhMotion", "read_bvh"]

_AXES = {"X": 0, "Y": 1, "Z": 2}


@dataclass
class BvhMotion:
    """A BVH clip after forward kinematics.

    Attributes:
        name: file stem, used in messages and to tell clips apart.
        joint_names: ``(J,)`` names, End Sites as ``<parent>_End``.
        parents: ``(J,)`` parent index, ``-1`` for the root.
        offsets: ``(J, 3)`` rest-pose offsets from the parent, file units.
        frame_time: seconds between frames.
        positions: ``(T, J, 3)`` global joint positions, file axes and units.
        rotations: ``(T, J, 3, 3)`` global joint rotation matrices (End Sites: their parent's).

    """

    name: str
    joint_names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    frame_time: float
    positions: np.ndarray
    rotations: np.ndarray

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.positions.shape[0])

    @property
    def rate(self) -> float:
        """Frames per second."""
        return 1.0 / self.frame_time

    @property
    def duration(self) -> float:
        """Seconds from the first to one frame past the last."""
        return self.n_frames * self.frame_time

    def index(self, joint_name: str) -> int:
        """Joint index by name; raises KeyError when absent."""
        return self.joint_names.index(joint_name)


@dataclass
class _Joint:
    name: str
    parent: int
    offset: np.ndarray
    channels: list[str]


def _parse_hierarchy(tokens: list[str], source: str) -> tuple[list[_Joint], int]:
    """Joints in file order (parents before children) and the token index after HIERARCHY."""
    joints: list[_Joint] = []
    stack: list[int] = []
    i = 1  # past "HIERARCHY"
    pending: _Joint | None = None
    while i < len(tokens):
        tok = tokens[i]
        if tok in {"ROOT", "JOINT"}:
            parent = stack[-1] if stack else -1
            pending = _Joint(tokens[i + 1], parent, np.zeros(3), [])
            i += 2
        elif tok == "End":
            parent = stack[-1]
            pending = _Joint(f"{joints[parent].name}_End", parent, np.zeros(3), [])
            i += 2
        elif tok == "{":
            if pending is None:
                msg = f"BVH file {source}: '{{' without a joint"
                raise RecordingError(msg)
            joints.append(pending)
            stack.append(len(joints) - 1)
            pending = None
            i += 1
        elif tok == "}":
            stack.pop()
            i += 1
        elif tok == "OFFSET":
            joints[stack[-1]].offset = np.array([float(v) for v in tokens[i + 1 : i + 4]])
            i += 4
        elif tok == "CHANNELS":
            count = int(tokens[i + 1])
            joints[stack[-1]].channels = tokens[i + 2 : i + 2 + count]
            i += 2 + count
        elif tok == "MOTION":
            return joints, i
        else:
            msg = f"BVH file {source}: unexpected token {tok!r} in the hierarchy"
            raise RecordingError(msg)
    msg = f"BVH file {source}: no MOTION section"
    raise RecordingError(msg)


def read_bvh(path: str | Path) -> BvhMotion:
    """Read a BVH file (plain or ``.gz``) and run forward kinematics on every frame.

    Raises:
        RecordingError: the file is missing or not a BVH file this reader understands.

    """
    path = Path(path)
    try:
        text = (
            gzip.decompress(path.read_bytes()).decode()
            if path.suffix == ".gz"
            else path.read_text()
        )
    except (OSError, UnicodeDecodeError, EOFError) as exc:
        msg = f"cannot read BVH file {path}: {exc}"
        raise RecordingError(msg) from exc
    head, sep, motion = text.partition("MOTION")
    if not sep or not head.lstrip().startswith("HIERARCHY"):
        msg = f"{path} is not a BVH file (it needs a HIERARCHY and a MOTION section)"
        raise RecordingError(msg)
    joints, _ = _parse_hierarchy([*head.split(), "MOTION"], str(path))
    frames_match = re.search(r"Frames:\s*(\d+)", motion)
    time_match = re.search(r"Frame Time:\s*([0-9.eE+-]+)", motion)
    if not frames_match or not time_match:
        msg = f"BVH file {path}: the MOTION section lacks 'Frames:' or 'Frame Time:'"
        raise RecordingError(msg)
    n_frames = int(frames_match.group(1))
    body = motion[time_match.end() :]
    n_channels = sum(len(j.channels) for j in joints)
    values = np.array(body.split(), dtype=float)
    if n_channels == 0 or values.size < n_frames * n_channels:
        msg = (
            f"BVH file {path}: expected {n_frames} frames of {n_channels} values, "
            f"found {values.size} values"
        )
        raise RecordingError(msg)
    values = values[: n_frames * n_channels].reshape(n_frames, n_channels)
    positions, rotations = _forward_kinematics(joints, values)
    return BvhMotion(
        name=path.name.split(".")[0],
        joint_names=tuple(j.name for j in joints),
        parents=np.array([j.parent for j in joints], dtype=np.int64),
        offsets=np.stack([j.offset for j in joints]),
        frame_time=float(time_match.group(1)),
        positions=positions,
        rotations=rotations,
    )


def _forward_kinematics(joints: list[_Joint], values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global positions ``(T, J, 3)`` and rotations ``(T, J, 3, 3)``, vectorised over frames.

    The loop runs over the joint tree (each joint needs its parent's result); every step works
    on all frames at once.
    """
    n_frames = values.shape[0]
    positions = np.zeros((n_frames, len(joints), 3))
    rotations = np.zeros((n_frames, len(joints), 3, 3))
    column = 0
    for j, joint in enumerate(joints):
        local_offset = np.tile(joint.offset, (n_frames, 1))
        order = ""
        angle_columns = []
        for k, channel in enumerate(joint.channels):
            if channel.endswith("position"):
                local_offset[:, _AXES[channel[0].upper()]] = values[:, column + k]
            else:
                order += channel[0].upper()
                angle_columns.append(column + k)
        column += len(joint.channels)
        if order:
            local = Rotation.from_euler(order, values[:, angle_columns], degrees=True).as_matrix()
        else:
            local = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
        if joint.parent < 0:
            rotations[:, j] = local
            positions[:, j] = local_offset
        else:
            parent_rot = rotations[:, joint.parent]
            rotations[:, j] = parent_rot @ local
            positions[:, j] = positions[:, joint.parent] + np.einsum(
                "tab,tb->ta", parent_rot, local_offset
            )
    return positions, rotations
