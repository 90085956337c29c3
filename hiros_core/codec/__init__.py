"""hiros_core.codec: SkeletonGroup and MarkerArray CDR bytes <-> the numpy model, no rclpy objects.

The bytes are those of ``rclpy.serialization.serialize_message`` for the same message (Fast-CDR,
little endian), except alignment padding, which Fast-CDR leaves uninitialised and we write as
zeros. Speed comes from plans (``hiros_core.cdr``): a shape (a skeleton's frame, marker ids and
names; a marker array's strings) is laid out once; after that encoding is a template copy plus
one numpy scatter per kind of value, and decoding one comparison plus one gather, whatever the
number of joints. SkeletonGroups are planned per skeleton, so groups mixing people and cameras
reuse the plans of their skeletons.

Conventions kept from DESIGN.md: markers and links are sparse and found by id; a link's id is its
child marker's id. Messages breaking that (duplicate or negative ids, a link whose id is not its
child) are refused with ``CodecError`` rather than silently altered.

Modules: ``group_plans`` (the SkeletonGroup plans and caches), ``group_encode``,
``group_decode``, ``marker_array`` (the MarkerArray codec) and ``fields`` (conversions both
share); the CDR plans themselves are ``hiros_core.cdr``.
"""

from hiros_core.codec.group_decode import decode_group
from hiros_core.codec.group_encode import encode_group, encode_group_into, warm_up
from hiros_core.codec.group_plans import (
    GROUP_HEADER,
    GROUP_PLANS,
    GROUP_READINGS,
    SKELETON_PLANS,
    STACK_PLANS,
)
from hiros_core.codec.marker_array import (
    MARKER_PLANS,
    MarkerArrayData,
    MarkerAttachments,
    MarkerFields,
    decode_marker_array,
    decode_marker_fields,
    encode_marker_array,
    marker_array_plan,
)

__all__ = [
    "MarkerArrayData",
    "MarkerAttachments",
    "MarkerFields",
    "clear_plan_caches",
    "decode_group",
    "decode_marker_array",
    "decode_marker_fields",
    "encode_group",
    "encode_group_into",
    "encode_marker_array",
    "marker_array_plan",
    "warm_up",
]


def clear_plan_caches() -> None:
    """Forget every cached plan (they are rebuilt on demand; for tests and memory)."""
    for cache in (SKELETON_PLANS, GROUP_HEADER, MARKER_PLANS):
        cache.by_key.clear()
    GROUP_PLANS.clear()
    STACK_PLANS.clear()
    GROUP_READINGS.clear()
    SKELETON_PLANS.by_phase.clear()
    GROUP_HEADER.by_size.clear()
    MARKER_PLANS.by_size.clear()
