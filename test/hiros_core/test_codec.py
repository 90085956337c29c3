"""The fast codec against rclpy's own serialisation, byte for byte (padding aside)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hiros_core import AZURE_KINECT, KINECT_V2, CodecError, Skeleton, SkeletonGroup
from hiros_core import cdr as cdr_module
from hiros_core.codec import (
    MarkerArrayData,
    MarkerAttachments,
    decode_group,
    decode_marker_array,
    encode_group,
    encode_group_into,
    encode_marker_array,
)
from hiros_core.model import stack_rows

serialization = pytest.importorskip("rclpy.serialization")
msgs = pytest.importorskip("hiros_skeleton_msgs.msg")
viz = pytest.importorskip("visualization_msgs.msg")

floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
names = st.text(
    st.characters(exclude_characters="\x00", exclude_categories=("Cs",)), max_size=40
)  # non-ASCII included
stamps = st.integers(min_value=-(2**31) * 10**9, max_value=(2**31 - 1) * 10**9 + 999_999_999)


@st.composite
def skeletons(draw: st.DrawFn) -> Skeleton:
    layout = draw(st.sampled_from([AZURE_KINECT, KINECT_V2]))
    skeleton = Skeleton.empty(
        layout,
        skeleton_id=draw(st.integers(-(2**31), 2**31 - 1)),
        src_time_ns=draw(stamps),
        src_frame=draw(names),
    )
    n = layout.n_joints
    skeleton.marker_present[:] = draw(st.lists(st.booleans(), min_size=n, max_size=n))
    skeleton.link_present[:] = draw(st.lists(st.booleans(), min_size=n, max_size=n))
    skeleton.link_present[0] = False  # the root has no link
    values = draw(st.lists(floats, min_size=40, max_size=40))
    rows = np.resize(np.array(values), (n, 20))
    skeleton.markers[skeleton.marker_present] = rows[skeleton.marker_present]
    skeleton.links[skeleton.link_present] = rows[::-1][skeleton.link_present]
    skeleton.confidence = draw(floats)
    skeleton.bounding_box[:] = np.resize(np.array(values), 22)
    skeleton.max_markers = draw(st.integers(0, 2**32 - 1))
    skeleton.max_links = draw(st.integers(0, 2**32 - 1))
    return skeleton


groups = st.builds(SkeletonGroup, stamps, names, st.lists(skeletons(), max_size=8))


def padding_free_equal(ours: bytes, theirs: bytes, encode_with_pad) -> bool:
    """Compare two encodings everywhere except where the encoder only wrote padding."""
    if len(ours) != len(theirs):
        return False
    filled = encode_with_pad()
    mask = np.frombuffer(filled, np.uint8) == np.frombuffer(ours, np.uint8)
    a, b = np.frombuffer(ours, np.uint8), np.frombuffer(theirs, np.uint8)
    return bool(np.array_equal(a[mask], b[mask]))


def encode_with_padding_byte(encode, value, fill: int) -> bytes:
    """Encode with padding filled by ``fill`` (to locate padding), bypassing the plan cache."""
    original = cdr_module.PlanBuilder.align

    def align(self, size: int) -> None:
        start = len(self.buf)
        original(self, size)
        self.buf[start:] = bytes([fill]) * (len(self.buf) - start)

    cdr_module.PlanBuilder.align = align
    try:
        from hiros_core import codec

        codec.clear_plan_caches()
        return encode(value)
    finally:
        cdr_module.PlanBuilder.align = original
        codec.clear_plan_caches()


def to_rclpy_group(group: SkeletonGroup):
    """The same group as rclpy message objects, built field by field from the model."""
    from hiros_bench.codec import _rclpy_group

    message = _rclpy_group(group)
    for skeleton, msg in zip(group.skeletons, message.skeletons, strict=True):
        box = msg.bounding_box
        values = skeleton.bounding_box.tolist()
        state = box.center
        p, o = state.pose.position, state.pose.orientation
        p.x, p.y, p.z, o.x, o.y, o.z, o.w = values[0:7]
        v, a = state.velocity, state.acceleration
        v.linear.x, v.linear.y, v.linear.z, v.angular.x, v.angular.y, v.angular.z = values[7:13]
        a.linear.x, a.linear.y, a.linear.z, a.angular.x, a.angular.y, a.angular.z = values[13:19]
        box.height, box.length, box.width = values[19:22]
    return message


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(groups)
def test_group_bytes_match_rclpy_and_round_trip(group: SkeletonGroup) -> None:
    theirs = serialization.serialize_message(to_rclpy_group(group))
    ours = encode_group(group)
    assert padding_free_equal(
        ours, theirs, lambda: encode_with_padding_byte(encode_group, group, 0xFF)
    )
    assert decode_group(ours).same_as(group)
    assert decode_group(theirs).same_as(group)  # rclpy's bytes, whatever their padding
    padded = encode_with_padding_byte(encode_group, group, 0xFF)  # (clears the caches)
    for raw in (padded, ours, theirs, padded):  # later reads recognise the learnt shape
        decoded = decode_group(raw)
        assert decoded.same_as(group)
        assert all(
            s.markers.shape == (s.layout.n_joints, 20) and s.links.shape == s.markers.shape
            for s in decoded.skeletons
        )
    decoded = decode_group(ours).skeletons
    for layout in {s.layout for s in decoded}:
        # a known shape: the skeletons of each layout are the rows of one stack (no copy)
        alike = [s for s in decoded if s.layout is layout]
        assert np.shares_memory(stack_rows(alike).markers, alike[0].markers)
        assert np.shares_memory(stack_rows(alike).links, alike[-1].links)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(groups, st.integers(0, 15))
def test_group_encoded_into_a_buffer_compiled_and_numpy_alike(
    group: SkeletonGroup, offset: int
) -> None:
    """``encode_group_into`` at any (unaligned) offset: its bytes alone, the numpy form's.

    The compiled filler (from the group's values, or from a stack of them) against its numpy
    form, ``group_encode._fill_numpy``.
    """
    for alike in (group, *restacked(group)):
        reference = _numpy_encoding(alike)
        buffer = np.full(len(reference) + 32, 0xA5, dtype=np.uint8)
        size = encode_group_into(alike, lambda n, b=buffer: (b, offset))
        assert size == len(reference)
        assert buffer[offset : offset + size].tobytes() == reference
        assert (np.delete(buffer, np.arange(offset, offset + size)) == 0xA5).all()


def _numpy_encoding(group: SkeletonGroup) -> bytes:
    """The group's bytes by the numpy form of the filler."""
    from hiros_core.codec import group_encode, group_plans

    plan = group_plans.plan_of(group)
    skeletons = group.skeletons
    values = np.concatenate(
        [a for s in skeletons for a in (s.bounding_box, s.markers, s.links)], axis=None
    ) if skeletons else np.empty(0)  # fmt: skip
    out = np.empty(plan.size, dtype=np.uint8)
    group_encode._fill_numpy(plan, group_encode._pack(plan, group), values, out, 0)
    return out.tobytes()


def restacked(group: SkeletonGroup) -> tuple[SkeletonGroup, SkeletonGroup]:
    """The group's skeletons of its first layout, as they are and as rows of one stack."""
    if not group.skeletons:
        return group, group
    layout = group.skeletons[0].layout
    alike = [s for s in group.skeletons if s.layout is layout]
    made = stack_rows(alike).skeletons(
        [s.id for s in alike], [s.src_time_ns for s in alike], "", layout,
        [s.confidence for s in alike],
    )  # fmt: skip
    for skeleton, original in zip(made, alike, strict=True):
        skeleton.src_frame = original.src_frame
        skeleton.max_markers, skeleton.max_links = original.max_markers, original.max_links
    return (
        SkeletonGroup(group.stamp_ns, group.frame_id, alike),
        SkeletonGroup(group.stamp_ns, group.frame_id, made),
    )


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(groups)
def test_groups_of_one_stack_encode_as_separate_skeletons(group: SkeletonGroup) -> None:
    """The compiled stack path (skeletons are rows of one SkeletonRows) gives the same bytes."""
    import numba  # noqa: F401 - the stack path runs when numba is loaded

    separate, stacked = restacked(group)
    assert encode_group(stacked) == encode_group(separate)
    for cut in (slice(1, None), slice(None, -1)):  # a slice of the stack is still one
        part = SkeletonGroup(group.stamp_ns, group.frame_id, stacked.skeletons[cut])
        assert encode_group(part) == encode_group(
            SkeletonGroup(group.stamp_ns, group.frame_id, separate.skeletons[cut])
        )
    if stacked.skeletons:  # a skeleton whose rows were replaced leaves the stack
        stacked.skeletons[0].markers = stacked.skeletons[0].markers + 1.0
        separate.skeletons[0].markers = separate.skeletons[0].markers + 1.0
        assert encode_group(stacked) == encode_group(separate)


@st.composite
def marker_arrays(draw: st.DrawFn) -> MarkerArrayData:
    n = draw(st.integers(0, 12))
    data = MarkerArrayData.new(n, frame_id=draw(names), stamp_ns=draw(stamps))
    data.ids[:] = draw(st.lists(st.integers(-(2**31), 2**31 - 1), min_size=n, max_size=n))
    data.actions[:] = draw(st.lists(st.sampled_from([0, 2, 3]), min_size=n, max_size=n))
    data.poses[:] = np.resize(np.array(draw(st.lists(floats, min_size=7, max_size=7))), (n, 7))
    data.texts = draw(st.lists(names, min_size=n, max_size=n))
    data.namespaces = draw(st.lists(names, min_size=n, max_size=n))
    data.points = [np.resize(np.arange(3.0 * k), (k, 3)) for k in range(n)]
    data.point_colors = [np.ones((k % 3, 4), dtype=np.float32) for k in range(n)]
    if n:
        data.attachments[0] = MarkerAttachments(
            texture_resource=draw(names),
            texture_data=b"\x01\x02\x03",
            uv_coordinates=((0.5, 0.25),),
            mesh_resource="package://x/y.dae",
            mesh_data=b"\x07" * 5,
        )
    return data


def to_rclpy_markers(data: MarkerArrayData):
    from geometry_msgs.msg import Point
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import UVCoordinate

    from hiros_bench.codec import _rclpy_markers

    message = _rclpy_markers(data)
    for i, marker in enumerate(message.markers):
        marker.ns, marker.text = data.namespaces[i], data.texts[i]
        marker.points = [Point(x=x, y=y, z=z) for x, y, z in data.points[i].tolist()]
        marker.colors = [
            ColorRGBA(r=r, g=g, b=b, a=a) for r, g, b, a in data.point_colors[i].tolist()
        ]
        extra = data.attachments[i]
        marker.texture_resource = extra.texture_resource
        marker.texture.data = list(extra.texture_data)
        marker.uv_coordinates = [UVCoordinate(u=u, v=v) for u, v in extra.uv_coordinates]
        marker.mesh_resource = extra.mesh_resource
        marker.mesh_file.data = list(extra.mesh_data)
    return message


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(marker_arrays())
def test_marker_array_bytes_match_rclpy_and_round_trip(data: MarkerArrayData) -> None:
    theirs = serialization.serialize_message(to_rclpy_markers(data))
    ours = encode_marker_array(data)
    assert padding_free_equal(
        ours, theirs, lambda: encode_with_padding_byte(encode_marker_array, data, 0xFF)
    )
    for decoded in (decode_marker_array(ours), decode_marker_array(theirs)):
        assert np.array_equal(decoded.ids, data.ids)
        assert np.array_equal(decoded.poses, data.poses, equal_nan=True)
        assert decoded.texts == data.texts
        assert decoded.namespaces == data.namespaces
        assert all(np.array_equal(a, b) for a, b in zip(decoded.points, data.points, strict=True))
        assert decoded.attachments == data.attachments


def test_second_decode_uses_the_plan_and_agrees() -> None:
    group = SkeletonGroup(7, "k", [Skeleton.from_positions(np.ones((32, 3)), skeleton_id=3)])
    data = encode_group(group)
    first, second = decode_group(data), decode_group(data)
    assert first.same_as(group)
    assert second.same_as(group)


def test_unsorted_markers_from_other_tools_decode() -> None:
    from hiros_skeleton_msgs.msg import Marker
    from hiros_skeleton_msgs.msg import Skeleton as SkeletonMsg
    from hiros_skeleton_msgs.msg import SkeletonGroup as GroupMsg

    from hiros_core.codec import clear_plan_caches
    from hiros_core.codec.group_plans import GROUP_READINGS

    message = GroupMsg(skeletons=[SkeletonMsg(id=1, max_markers=32)])
    for joint in (5, 0, 31):
        marker = Marker(id=joint, name=AZURE_KINECT.joint_names[joint], confidence=0.5)
        marker.center.pose.position.x = float(joint)
        message.skeletons[0].markers.append(marker)
    data = serialization.serialize_message(message)
    clear_plan_caches()
    for _ in range(2):  # no plan writes markers out of order: the field reader, each time
        group = decode_group(data)
        skeleton = group.skeletons[0]
        assert skeleton.layout is AZURE_KINECT
        assert np.flatnonzero(skeleton.marker_present).tolist() == [0, 5, 31]
        assert skeleton.positions[31, 0] == 31.0
    assert len(data) not in GROUP_READINGS  # and no reading that cannot read it is kept


def test_unknown_names_make_a_decoded_layout_that_re_encodes() -> None:
    from hiros_skeleton_msgs.msg import Link, Marker
    from hiros_skeleton_msgs.msg import Skeleton as SkeletonMsg
    from hiros_skeleton_msgs.msg import SkeletonGroup as GroupMsg

    skeleton = SkeletonMsg(id=2, max_markers=3, max_links=3)
    skeleton.markers = [Marker(id=0, name="root"), Marker(id=2, name="tip")]
    skeleton.links = [Link(id=2, name="bone", parent_marker=0, child_marker=2)]
    data = serialization.serialize_message(GroupMsg(skeletons=[skeleton]))
    group = decode_group(data)
    assert group.skeletons[0].layout.joint_names[2] == "tip"
    ours = encode_group(group)
    assert padding_free_equal(
        ours, data, lambda: encode_with_padding_byte(encode_group, group, 0xFF)
    )


@pytest.mark.parametrize("cut", [0, 3, 4, 11, 100, -9, -1])
def test_truncated_group_raises_codec_error(cut: int) -> None:
    group = SkeletonGroup(1, "k01", [Skeleton.from_positions(np.zeros((32, 3)))])
    data = encode_group(group)
    with pytest.raises(CodecError, match="SkeletonGroup"):
        decode_group(data[:cut])


def test_corrupt_counts_raise_codec_error() -> None:
    data = bytearray(encode_group(SkeletonGroup(1, "k", [Skeleton.empty()])))
    data[20:24] = (2**31).to_bytes(4, "little")  # absurd number of skeletons
    with pytest.raises(CodecError):
        decode_group(bytes(data))
    with pytest.raises(CodecError, match="encapsulation"):
        decode_group(b"\x07\x07\x00\x00" + bytes(40))


def test_out_of_range_values_are_refused_when_encoding() -> None:
    skeleton = Skeleton.empty()
    skeleton.id = 2**40
    with pytest.raises(CodecError, match="id"):
        encode_group(SkeletonGroup(0, "", [skeleton]))


def test_nan_and_inf_survive() -> None:
    skeleton = Skeleton.from_positions(np.ones((32, 3)))
    skeleton.velocities[0] = [math.inf, -math.inf, math.nan]
    decoded = decode_group(encode_group(SkeletonGroup(0, "", [skeleton]))).skeletons[0]
    assert decoded.velocities[0, 0] == math.inf
    assert math.isnan(decoded.velocities[0, 2])


def test_embedded_nul_ends_a_string_as_in_rclpy() -> None:
    group = SkeletonGroup(0, "k01\x00junk", [])
    theirs = serialization.serialize_message(to_rclpy_group(group))
    ours = encode_group(group)
    assert padding_free_equal(
        ours, theirs, lambda: encode_with_padding_byte(encode_group, group, 0xFF)
    )
    assert decode_group(theirs).frame_id == "k01"


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(marker_arrays(), st.booleans())
def test_fast_walk_of_new_shapes_reads_as_the_field_reader(data, media) -> None:
    """A new shape is walked by ``_walk_marker_array``: same columns as the field-by-field
    reader, whatever the padding bytes hold; media attachments and bad bytes go the reader's
    way (same columns, same errors).
    """
    from hiros_core.codec.marker_array import _parse_marker_array, _walk_marker_array

    if not media:
        data.attachments = []
        data.__post_init__()
    for raw in (
        encode_marker_array(data),
        encode_with_padding_byte(encode_marker_array, data, 0xFF),
    ):
        walked, read = _walk_marker_array(raw), _parse_marker_array(raw)
        for name in ("ids", "types", "actions", "stamps_ns", "lifetimes_ns", "frame_locked"):
            assert np.array_equal(getattr(walked, name), getattr(read, name))
            assert getattr(walked, name).dtype == getattr(read, name).dtype
        for name in ("poses", "scales", "colors"):
            assert np.array_equal(getattr(walked, name), getattr(read, name), equal_nan=True)
        for name in ("frame_ids", "namespaces", "texts", "attachments"):
            assert getattr(walked, name) == getattr(read, name)
        for name in ("points", "point_colors"):
            pairs = zip(getattr(walked, name), getattr(read, name), strict=True)
            assert all(a.shape == b.shape and np.array_equal(a, b) for a, b in pairs)
        for cut in (1, len(raw) // 2):
            with pytest.raises(CodecError):
                _walk_marker_array(raw[:-cut])


def test_decoded_layouts_of_different_joints_have_different_names() -> None:
    """Stages keep per-layout state by name: two decoded layouts must never share one."""
    from hiros_skeleton_msgs.msg import Marker
    from hiros_skeleton_msgs.msg import Skeleton as SkeletonMsg
    from hiros_skeleton_msgs.msg import SkeletonGroup as GroupMsg

    def layout_of(n_markers: int) -> object:
        skeleton = SkeletonMsg(id=1, max_markers=n_markers)
        skeleton.markers = [Marker(id=i, name="x") for i in range(n_markers)]
        data = serialization.serialize_message(GroupMsg(skeletons=[skeleton]))
        return decode_group(data).skeletons[0].layout

    small, large, again = layout_of(3), layout_of(32), layout_of(3)
    assert small.name != large.name
    assert again.name == small.name
