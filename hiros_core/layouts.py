"""Skeleton layouts: which joints a body-tracking driver reports and how they connect.

A layout is the one table every stage consults for joint names, parents, limbs (links) and the
left/right mirror permutation. The Azure Kinect Body Tracking SDK (32 joints) and Kinect v2
(25 joints) are built in; any other driver is described in a small YAML file::

    name: my_driver
    joints: [Pelvis, SpineNaval, ...]    # index = marker id
    parents: [-1, 0, ...]                # parent joint index, -1 for the root

For the Azure Kinect layout the marker id is the SDK joint index and a link's id is its child
joint's id (DESIGN.md), so link ids run 1..31 and link 0 never exists.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from hiros_core.errors import LayoutError
from hiros_core.kinematics import KinematicTree
from hiros_core.safe_yaml import load_yaml

__all__ = [
    "AZURE_KINECT",
    "KINECT_V2",
    "BodyJoints",
    "Layout",
    "get_layout",
    "load_layout",
]


_SPINE = ("SpineNaval", "SpineMid", "SpineChest", "SpineShoulder", "Neck")
"""Joints between the root and the head, bottom up (Azure Kinect and Kinect v2 names)."""


@dataclass(frozen=True)
class BodyJoints:
    """The joints a body's own axes come from, found by name (Azure Kinect and Kinect v2).

    Left minus right gives the body's sides, root to neck its up, and the pointers (ankle ->
    foot, head -> nose) where it faces. The tracker decides facing from them and the merger
    reflects flipped views with them, so both read the same joints in the same order.

    Attributes:
        root: the layout's root joint.
        neck: the neck, ``-1`` when the layout has none.
        left: ``(hip, shoulder)`` on the left, ``-1`` where the layout has none.
        right: ``(hip, shoulder)`` on the right, ``-1`` where the layout has none.
        torso: the root, then the spine joints up to the neck, bottom up.
        feet: ``(ankle, foot)`` left then right, those the layout has both joints of.
        head: ``(head, nose)``, or empty when the layout lacks either.

    """

    root: int
    neck: int
    left: tuple[int, int]
    right: tuple[int, int]
    torso: tuple[int, ...]
    feet: tuple[tuple[int, int], ...]
    head: tuple[int, ...]

    @classmethod
    def of(cls, layout: Layout) -> BodyJoints:
        """Look the joints up in ``layout`` by name."""
        index = {name: i for i, name in enumerate(layout.joint_names)}
        root = layout.parents.index(-1)

        def pair(a: str, b: str) -> tuple[int, ...]:
            return (index[a], index[b]) if a in index and b in index else ()

        feet = (pair("AnkleLeft", "FootLeft"), pair("AnkleRight", "FootRight"))
        return cls(
            root=root,
            neck=index.get("Neck", -1),
            left=(index.get("HipLeft", -1), index.get("ShoulderLeft", -1)),
            right=(index.get("HipRight", -1), index.get("ShoulderRight", -1)),
            torso=(root, *(index[name] for name in _SPINE if name in index)),
            feet=tuple(f for f in feet if f),
            head=pair("Head", "Nose"),
        )

    @property
    def sides(self) -> tuple[np.ndarray, np.ndarray]:
        """``(k,)`` left and right joints of the pairs the layout has both of (hips, shoulders)."""
        both = [(a, b) for a, b in zip(self.left, self.right, strict=True) if a >= 0 and b >= 0]
        left = np.array([a for a, _ in both], dtype=np.int64)
        right = np.array([b for _, b in both], dtype=np.int64)
        return left, right


@dataclass(frozen=True)
class Layout:
    """The joints of one driver's skeleton and the tree that links them.

    Attributes:
        name: short identifier (``azure_kinect``, ``kinect_v2``, ...).
        joint_names: name of each joint; the index is the marker id.
        parents: ``(J,)`` parent joint index of each joint, ``-1`` for the root.
        link_labels: names of the links by link id, when they are not ``Parent-Child``
            (layouts decoded from other tools' messages keep those tools' names).

    """

    name: str
    joint_names: tuple[str, ...]
    parents: tuple[int, ...]
    link_labels: tuple[str, ...] | None = None
    _index: dict[str, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if len(self.joint_names) != len(self.parents):
            msg = (
                f"layout {self.name!r} has {len(self.joint_names)} joints "
                f"but {len(self.parents)} parents"
            )
            raise LayoutError(msg)
        for joint, parent in enumerate(self.parents):
            if parent >= len(self.parents) or parent < -1 or parent == joint:
                msg = f"layout {self.name!r}: joint {joint} has invalid parent {parent}"
                raise LayoutError(msg)
        if self.link_labels is not None and len(self.link_labels) != len(self.joint_names):
            msg = f"layout {self.name!r} needs one link label per joint id"
            raise LayoutError(msg)
        index: dict[str, int] = {}
        for joint, name in enumerate(self.joint_names):
            index.setdefault(name, joint)
        object.__setattr__(self, "_index", index)

    @property
    def n_joints(self) -> int:
        """Number of joints J, which is also ``max_markers`` in messages."""
        return len(self.joint_names)

    @property
    def n_links(self) -> int:
        """``max_links`` in messages: link ids are child joint ids, so this equals J."""
        return len(self.joint_names)

    def index(self, joint_name: str) -> int:
        """Marker id of a joint by name; raises LayoutError for an unknown name."""
        try:
            return self._index[joint_name]
        except KeyError:
            msg = f"layout {self.name!r} has no joint named {joint_name!r}"
            raise LayoutError(msg) from None

    @cached_property
    def link_children(self) -> np.ndarray:
        """``(L,)`` child joint of each link, which is also the link id (roots excluded)."""
        return np.array([j for j, p in enumerate(self.parents) if p >= 0], dtype=np.int32)

    @cached_property
    def link_parents(self) -> np.ndarray:
        """``(L,)`` parent joint of each link, aligned with ``link_children``."""
        return np.array([self.parents[c] for c in self.link_children], dtype=np.int32)

    @cached_property
    def link_names(self) -> tuple[str, ...]:
        """Name of each link id (``""`` for ids with no link, such as the root)."""
        if self.link_labels is not None:
            return self.link_labels
        names = [""] * self.n_links
        for parent, child in zip(self.link_parents, self.link_children, strict=True):
            names[child] = f"{self.joint_names[parent]}-{self.joint_names[child]}"
        return tuple(names)

    @cached_property
    def mirror(self) -> np.ndarray:
        """``(J,)`` permutation that swaps left and right joints (identity on the midline).

        ``positions[layout.mirror]`` is what a driver reports when it confuses the sides.
        """
        perm = np.arange(self.n_joints)
        for joint, name in enumerate(self.joint_names):
            for side, other in (("Left", "Right"), ("Right", "Left")):
                if side in name:
                    perm[joint] = self._index.get(name.replace(side, other), joint)
        return perm

    @cached_property
    def body(self) -> BodyJoints:
        """The joints the body's own axes come from (sides, up, facing), by name."""
        return BodyJoints.of(self)

    @cached_property
    def tree(self) -> KinematicTree:
        """The joint tree's index tables (levels, subtrees, parents before children)."""
        return KinematicTree.from_layout(self)


_AZURE_JOINTS = (
    ("Pelvis", -1), ("SpineNaval", 0), ("SpineChest", 1), ("Neck", 2),
    ("ClavicleLeft", 2), ("ShoulderLeft", 4), ("ElbowLeft", 5), ("WristLeft", 6),
    ("HandLeft", 7), ("HandTipLeft", 8), ("ThumbLeft", 7),
    ("ClavicleRight", 2), ("ShoulderRight", 11), ("ElbowRight", 12), ("WristRight", 13),
    ("HandRight", 14), ("HandTipRight", 15), ("ThumbRight", 14),
    ("HipLeft", 0), ("KneeLeft", 18), ("AnkleLeft", 19), ("FootLeft", 20),
    ("HipRight", 0), ("KneeRight", 22), ("AnkleRight", 23), ("FootRight", 24),
    ("Head", 3), ("Nose", 26), ("EyeLeft", 26), ("EarLeft", 26), ("EyeRight", 26),
    ("EarRight", 26),
)  # fmt: skip

_KINECT_V2_JOINTS = (
    ("SpineBase", -1), ("SpineMid", 0), ("Neck", 20), ("Head", 2),
    ("ShoulderLeft", 20), ("ElbowLeft", 4), ("WristLeft", 5), ("HandLeft", 6),
    ("ShoulderRight", 20), ("ElbowRight", 8), ("WristRight", 9), ("HandRight", 10),
    ("HipLeft", 0), ("KneeLeft", 12), ("AnkleLeft", 13), ("FootLeft", 14),
    ("HipRight", 0), ("KneeRight", 16), ("AnkleRight", 17), ("FootRight", 18),
    ("SpineShoulder", 1), ("HandTipLeft", 7), ("ThumbLeft", 6), ("HandTipRight", 11),
    ("ThumbRight", 10),
)  # fmt: skip

AZURE_KINECT = Layout(
    "azure_kinect",
    tuple(n for n, _ in _AZURE_JOINTS),
    tuple(p for _, p in _AZURE_JOINTS),
)
"""Azure Kinect Body Tracking SDK (k4abt) joints, in SDK index order."""

KINECT_V2 = Layout(
    "kinect_v2",
    tuple(n for n, _ in _KINECT_V2_JOINTS),
    tuple(p for _, p in _KINECT_V2_JOINTS),
)
"""Kinect for Windows v2 joints, in SDK ``JointType`` order."""

_BUILTIN = {layout.name: layout for layout in (AZURE_KINECT, KINECT_V2)}


def load_layout(path: str | Path) -> Layout:
    """Read a layout from a YAML file with ``name``, ``joints`` and ``parents``."""
    path = Path(path)
    spec = load_yaml(path, what="layout file", error=LayoutError)
    if not isinstance(spec, dict) or not {"joints", "parents"} <= spec.keys():
        msg = f"layout file {path} must be a mapping with 'joints' and 'parents'"
        raise LayoutError(msg)
    joints = [str(j) for j in spec["joints"]]
    if len(set(joints)) != len(joints):
        msg = f"layout file {path} names a joint twice"
        raise LayoutError(msg)
    return Layout(
        str(spec.get("name", path.stem)),
        tuple(joints),
        tuple(int(p) for p in spec["parents"]),
    )


def get_layout(name_or_path: str | Path) -> Layout:
    """A built-in layout by name (``azure_kinect``, ``kinect_v2``) or one loaded from YAML."""
    if str(name_or_path) in _BUILTIN:
        return _BUILTIN[str(name_or_path)]
    if Path(name_or_path).suffix in {".yaml", ".yml"}:
        return load_layout(name_or_path)
    msg = f"unknown skeleton layout {name_or_path!r}; use one of {sorted(_BUILTIN)} or a YAML file"
    raise LayoutError(msg)
