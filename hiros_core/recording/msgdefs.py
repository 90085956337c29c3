"""Full ROS 2 message definitions (``ros2msg``) to embed in MCAP schemas, as rosbag2 writes them.

``ros2 bag`` and Foxglove decode a topic from the schema stored beside it: the top-level
``.msg`` text first, then every type it uses, recursively, each after a delimiter line of 80
``=`` and a ``MSG: <type>`` line (rosbag2's "message definition encoding"). The text is laid
out byte for byte as rosbag2 Jazzy's ``LocalMessageDefinitionSource::get_full_text`` lays it
out (ros2/rosbag2, ``rosbag2_cpp/src/rosbag2_cpp/message_definitions/
local_message_definition_source.cpp``): a type is labelled as the field that names it spells
it (``MSG: std_msgs/Header``; a type of the same package named bare, ``Skeleton``, becomes
``hiros_skeleton_msgs/Skeleton``), each type's dependencies follow it depth first in sorted
order, and each delimiter is preceded by an empty line. Foxglove's ``@foxglove/rosmsg`` looks a
field's type up by that spelling: a label ``std_msgs/msg/Header`` for a field
``std_msgs/Header`` leaves the type undefined for it.

The texts are never typed by hand here; they come from, in order:

1. this repository's ``hiros_skeleton_msgs/msg`` folder (our own messages);
2. the ``share/<package>/msg/<Type>.msg`` files of installed ROS packages
   (``AMENT_PREFIX_PATH`` and the Python environment's prefix);
3. the ROS 2 Jazzy type store shipped by ``rosbags``, for packages not installed here,
   whose text is the definition without comments.

``type_hash`` gives a type's REP-2011 hash (``RIHS01_...``), which rosbag2 Jazzy records as
each channel's ``topic_type_hash``.
"""

from __future__ import annotations

import os
import re
import sys
from functools import cache
from pathlib import Path

from hiros_core.errors import RecordingError

__all__ = ["message_definition", "normalize_msgtype", "type_hash"]

DELIMITER = "=" * 80
_REPO_MSGS = Path(__file__).resolve().parents[2] / "hiros_skeleton_msgs" / "msg"
_PRIMITIVES = frozenset(
    [
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "string",
        "wstring",
    ]
)
# A field's type at the start of a line (rosbag2's MSG_FIELD_TYPE_REGEX): comment lines and
# bounded strings (``string<=5``) do not match, constants give their primitive type.
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")


def normalize_msgtype(msgtype: str) -> str:
    """``std_msgs/Header`` or ``std_msgs/msg/Header`` -> ``std_msgs/msg/Header``."""
    parts = msgtype.strip("/").split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 3 and parts[1] == "msg":
        return "/".join(parts)
    msg = f"{msgtype!r} is not a message type name such as std_msgs/msg/String"
    raise RecordingError(msg)


def _share_dirs() -> list[Path]:
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return [Path(p) / "share" for p in dict.fromkeys(prefixes)]


@cache
def _own_text(msgtype: str) -> str:
    """The ``.msg`` text of one type (no dependencies)."""
    package, _, name = msgtype.split("/")
    candidates = [Path(d) / package / "msg" / f"{name}.msg" for d in _share_dirs()]
    if package == "hiros_skeleton_msgs":
        candidates.insert(0, _REPO_MSGS / f"{name}.msg")
    for path in candidates:
        if path.is_file():
            return path.read_text()
    return _typestore_text(msgtype)


def _typestore_text(msgtype: str) -> str:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    if msgtype not in store.fielddefs:
        msg = (
            f"no message definition found for {msgtype} (not in this repository, not installed "
            "under AMENT_PREFIX_PATH, not in the ROS 2 Jazzy type store)"
        )
        raise RecordingError(msg)
    text, _ = store.generate_msgdef(msgtype, ros_version=2)
    return text.split(f"{DELIMITER}\n", 1)[0]


def _dependencies(msgtype: str, text: str) -> list[str]:
    """The message types the fields of ``text`` name, spelled as rosbag2 labels them, sorted.

    A bare name is a type of the same package (``Skeleton`` in a ``hiros_skeleton_msgs``
    type); a bare ``Header`` is ``std_msgs/Header``, as rosidl reads it.
    """
    package = msgtype.split("/", maxsplit=1)[0]
    found: set[str] = set()
    for match in _FIELD_TYPE.finditer(text):
        kind = match.group(1)
        if kind in _PRIMITIVES:
            continue
        if kind == "Header":  # ROS 1 shorthand, still accepted by rosidl
            kind = "std_msgs/Header"
        found.add(kind if "/" in kind else f"{package}/{kind}")
    return sorted(found)


@cache
def message_definition(msgtype: str) -> str:
    """The complete ``ros2msg`` definition of ``msgtype``, dependencies included.

    Raises:
        RecordingError: the type or one of its dependencies has no known definition.

    """
    top = normalize_msgtype(msgtype)
    seen: set[str] = set()

    def full_text(name: str, label: str) -> str:
        text = _own_text(name)
        for dependency in _dependencies(label, text):
            if dependency not in seen:
                seen.add(dependency)
                text += f"\n{DELIMITER}\nMSG: {dependency}\n"
                text += full_text(normalize_msgtype(dependency), dependency)
        return text

    return full_text(top, top)


@cache
def type_hash(msgtype: str) -> str:
    """REP-2011 type hash (``RIHS01_<sha256>``) of ``msgtype``, as rosidl computes it.

    From ``rosbags``' ROS 2 Jazzy type store, with the types of ``message_definition`` that
    it lacks (our own) registered from their text.

    Raises:
        RecordingError: the type or one of its dependencies has no known definition.

    """
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    top = normalize_msgtype(msgtype)
    store = get_typestore(Stores.ROS2_JAZZY)
    if top not in store.fielddefs:
        types = get_types_from_msg(message_definition(top), top)
        store.register({k: v for k, v in types.items() if k not in store.fielddefs})
    return store.hash_rihs01(top)
