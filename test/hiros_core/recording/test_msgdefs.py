"""Complete ros2msg definitions: every dependency present, labelled as rosbag2 labels it."""

import json
import re
import sys
from pathlib import Path

import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from hiros_core.errors import RecordingError
from hiros_core.recording import message_definition
from hiros_core.recording.msgdefs import DELIMITER, normalize_msgtype, type_hash

TYPES = [
    "hiros_skeleton_msgs/msg/SkeletonGroup",
    "hiros_skeleton_msgs/msg/StampedSkeleton",
    "visualization_msgs/msg/MarkerArray",
    "tf2_msgs/msg/TFMessage",
    "diagnostic_msgs/msg/DiagnosticArray",
    "std_msgs/msg/String",
    "rosgraph_msgs/msg/Clock",
]


@pytest.mark.parametrize("msgtype", TYPES)
def test_definition_is_complete_and_parses(msgtype):
    text = message_definition(msgtype)
    types = get_types_from_msg(text, msgtype)
    assert msgtype in types
    # every type a field names is defined in the text
    for _, fields in types.values():
        for _, (kind, detail) in fields:
            inner = detail[0] if kind in (3, 4) else (kind, detail)  # ARRAY, SEQUENCE
            if inner[0] == 2:  # NAME
                assert inner[1] in types, inner[1]
    sections = text.split(f"\n{DELIMITER}\n")
    headers = [s.split("\n", 1)[0] for s in sections[1:]]
    assert len(set(headers)) == len(headers)
    # each type is labelled as the fields name it (package/Type), which Foxglove looks up
    named = {
        f"{section_type.split('/')[0]}/{kind}" if "/" not in kind else kind
        for section_type, section in zip(
            [msgtype] + [h.removeprefix("MSG: ") for h in headers], sections, strict=True
        )
        for kind in re.findall(r"^\s*([A-Za-z][\w/]*)(?:\[[^\]]*\])?\s", section, re.M)
        if kind[0].isupper() or "/" in kind
    }
    assert all(h.startswith("MSG: ") for h in headers)
    assert {h.removeprefix("MSG: ") for h in headers} == named
    assert all(h.count("/") == 1 for h in headers)


def test_rosbag2_layout():
    """rosbag2 Jazzy's order: depth first, each type's dependencies sorted, an empty line
    before each delimiter; the texts unchanged."""
    text = message_definition("geometry_msgs/msg/PoseStamped")
    sections = text.split(f"\n{DELIMITER}\n")
    assert [s.split("\n", 1)[0] for s in sections[1:]] == [
        "MSG: geometry_msgs/Pose",
        "MSG: geometry_msgs/Point",
        "MSG: geometry_msgs/Quaternion",
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
    ]
    assert all(s.endswith("\n") for s in sections)  # each .msg text keeps its last newline


def test_type_hash_is_rosidls():
    """REP-2011 hashes equal those rosidl wrote beside the installed interfaces."""
    compared = 0
    for msgtype in TYPES:
        package, _, name = msgtype.split("/")
        found = Path(sys.prefix, "share", package, "msg", f"{name}.json")
        if not found.is_file():
            continue
        hashes = json.loads(found.read_text())["type_hashes"]
        expected = next(h["hash_string"] for h in hashes if h["type_name"] == msgtype)
        assert type_hash(msgtype) == expected, msgtype
        compared += 1
    if not compared:
        pytest.skip("no rosidl type description (.json) installed in this environment")


def test_standard_types_match_jazzy_layout():
    store = get_typestore(Stores.ROS2_JAZZY)
    name = "visualization_msgs/msg/MarkerArray"
    ours = get_types_from_msg(message_definition(name), name)
    for name, (_, fields) in ours.items():
        assert [f for f, _ in fields] == [f for f, _ in store.fielddefs[name][1]], name


def test_own_messages_keep_their_text():
    text = message_definition("hiros_skeleton_msgs/msg/SkeletonGroup")
    assert text.startswith("std_msgs/Header header\nSkeleton[] skeletons\n")
    assert "MSG: hiros_skeleton_msgs/KinematicState\n" in text
    assert "# Two-integer timestamp" in text  # installed .msg texts keep their comments


def test_unknown_types_and_names():
    with pytest.raises(RecordingError, match="no message definition"):
        message_definition("nobody_msgs/msg/Nothing")
    with pytest.raises(RecordingError, match="not a message type"):
        normalize_msgtype("String")
    assert normalize_msgtype("/std_msgs/String") == "std_msgs/msg/String"
