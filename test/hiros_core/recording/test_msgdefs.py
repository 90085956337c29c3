"""Complete ros2msg definitions: every dependency present, parseable by other tools."""

import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from hiros_core.errors import RecordingError
from hiros_core.recording import message_definition
from hiros_core.recording.msgdefs import DELIMITER, normalize_msgtype

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
    sections = text.split(DELIMITER + "\n")
    headers = [s.split("\n", 1)[0] for s in sections[1:]]
    assert all(h.startswith("MSG: ") and h.count("/") == 2 for h in headers)
    assert len(set(headers)) == len(headers)


def test_standard_types_match_jazzy_layout():
    store = get_typestore(Stores.ROS2_JAZZY)
    name = "visualization_msgs/msg/MarkerArray"
    ours = get_types_from_msg(message_definition(name), name)
    for name, (_, fields) in ours.items():
        assert [f for f, _ in fields] == [f for f, _ in store.fielddefs[name][1]], name


def test_own_messages_keep_their_text():
    text = message_definition("hiros_skeleton_msgs/msg/SkeletonGroup")
    assert text.startswith("std_msgs/Header header\nSkeleton[] skeletons\n")
    assert "MSG: hiros_skeleton_msgs/msg/KinematicState\n" in text
    assert "# Two-integer timestamp" in text  # installed .msg texts keep their comments


def test_unknown_types_and_names():
    with pytest.raises(RecordingError, match="no message definition"):
        message_definition("nobody_msgs/msg/Nothing")
    with pytest.raises(RecordingError, match="not a message type"):
        normalize_msgtype("String")
    assert normalize_msgtype("/std_msgs/String") == "std_msgs/msg/String"
