"""Every field of hiros_skeleton_msgs, by name, type and order, as Hi-ROS defines them."""

from __future__ import annotations

import importlib

import pytest

pytest.importorskip("hiros_skeleton_msgs.msg")

KINEMATIC_STATE = [
    ("pose", "geometry_msgs/Pose"),
    ("velocity", "geometry_msgs/Twist"),
    ("acceleration", "geometry_msgs/Accel"),
]
SKELETON = [
    ("id", "int32"),
    ("src_time", "builtin_interfaces/Time"),
    ("src_frame", "string"),
    ("max_markers", "uint32"),
    ("max_links", "uint32"),
    ("confidence", "double"),
    ("bounding_box", "hiros_skeleton_msgs/Box"),
    ("markers", "sequence<hiros_skeleton_msgs/Marker>"),
    ("links", "sequence<hiros_skeleton_msgs/Link>"),
]
MESSAGES = {
    "KinematicState": KINEMATIC_STATE,
    "Box": [
        ("center", "hiros_skeleton_msgs/KinematicState"),
        ("height", "double"),
        ("length", "double"),
        ("width", "double"),
    ],
    "Marker": [
        ("id", "int32"),
        ("name", "string"),
        ("confidence", "double"),
        ("center", "hiros_skeleton_msgs/KinematicState"),
    ],
    "Link": [
        ("id", "int32"),
        ("name", "string"),
        ("parent_marker", "int32"),
        ("child_marker", "int32"),
        ("confidence", "double"),
        ("center", "hiros_skeleton_msgs/KinematicState"),
    ],
    "Skeleton": SKELETON,
    "StampedSkeleton": [("header", "std_msgs/Header"), *SKELETON],
    "SkeletonGroup": [
        ("header", "std_msgs/Header"),
        ("skeletons", "sequence<hiros_skeleton_msgs/Skeleton>"),
    ],
}
SERVICES = {
    "ChangeId": ([("from_id", "int32"), ("to_id", "int32")], [("ok", "boolean")]),
    "Calibrate": ([("track_ids", "sequence<int32>")], [("ok", "boolean")]),
}


@pytest.mark.parametrize(("name", "fields"), MESSAGES.items())
def test_message_fields_in_order(name: str, fields: list[tuple[str, str]]) -> None:
    message = getattr(importlib.import_module("hiros_skeleton_msgs.msg"), name)
    assert list(message.get_fields_and_field_types().items()) == fields


@pytest.mark.parametrize(("name", "fields"), SERVICES.items())
def test_service_fields(name: str, fields: tuple) -> None:
    service = getattr(importlib.import_module("hiros_skeleton_msgs.srv"), name)
    request, response = fields
    assert list(service.Request.get_fields_and_field_types().items()) == request
    assert list(service.Response.get_fields_and_field_types().items()) == response


def test_type_hashes_agree_with_an_independent_implementation() -> None:
    """rosidl's RIHS01 hash of each type equals the one rosbags computes from the .msg text.

    The hash covers names, types and order of every field (recursively), so a table-identical
    definition gives Hi-ROS's hash: Hi-ROS nodes and ours can share topics on Jazzy.
    """
    import json
    import sys
    from pathlib import Path

    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    REPO = Path(__file__).resolve().parents[2]

    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for path in sorted((REPO / "hiros_skeleton_msgs" / "msg").glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"hiros_skeleton_msgs/msg/{path.stem}"))
    store.register(types)
    share = Path(sys.prefix) / "share" / "hiros_skeleton_msgs" / "msg"
    if not share.is_dir():
        pytest.skip("messages not installed in this prefix")
    for name in MESSAGES:
        description = json.loads((share / f"{name}.json").read_text())
        rosidl_hash = description["type_hashes"][0]["hash_string"]
        assert rosidl_hash == store.hash_rihs01(f"hiros_skeleton_msgs/msg/{name}"), name
