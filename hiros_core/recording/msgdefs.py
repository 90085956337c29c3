"""Full ROS 2 message definitions (``ros2msg``) to embed in MCAP schemas.

``ros2 bag`` and Foxglove decode a topic from the schema stored beside it: the top-level
``.msg`` text first, then every type it uses, recursively, each after a delimiter line of 80
``=`` and a ``MSG: <package>/msg/<Type>`` line (rosbag2's "message definition encoding").
The texts are never typed by hand here; they come from, in order:

1. this repository's ``hiros_skeleton_msgs/msg`` folder (our own messages);
2. the ``share/<package>/msg/<Type>.msg`` files of installed ROS packages
   (``AMENT_PREFIX_PATH`` and the Python environment's prefix);
3. the ROS 2 Jazzy type store shipped by ``rosbags``, for packages not installed here
   (``tf2_msgs``), whose text is the definition without comments.
"""

from __future__ import annotations

import os
import re
import sys
from functools import cache
from pathlib import Path

from hiros_core.errors import RecordingError

__all__ = ["message_definition", "normalize_msgtype"]

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
_BOUND = re.compile(r"(<=\d+)?(\[[^\]]*\])?$")


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
    """Message types named by the fields of ``text``, in order of appearance."""
    package = msgtype.split("/", maxsplit=1)[0]
    found: list[str] = []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        kind = line.split()[0]
        base = _BOUND.sub("", kind)
        if base in _PRIMITIVES or "=" in line.split(None, 1)[-1].split()[0]:
            continue
        if base == "Header":  # ROS 1 shorthand, still accepted by rosidl
            base = "std_msgs/Header"
        found.append(normalize_msgtype(base if "/" in base else f"{package}/{base}"))
    return found


@cache
def message_definition(msgtype: str) -> str:
    """The complete ``ros2msg`` definition of ``msgtype``, dependencies included.

    Raises:
        RecordingError: the type or one of its dependencies has no known definition.

    """
    top = normalize_msgtype(msgtype)
    order: list[str] = []
    pending = [top]
    while pending:
        current = pending.pop(0)
        if current in order:
            continue
        order.append(current)
        pending.extend(_dependencies(current, _own_text(current)))
    sections = [_own_text(top).rstrip("\n")]
    sections += [f"{DELIMITER}\nMSG: {t}\n{_own_text(t).rstrip(chr(10))}" for t in order[1:]]
    return "\n".join(sections) + "\n"
