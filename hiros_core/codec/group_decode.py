"""CDR bytes -> SkeletonGroup: a known message by one gather, a new one skeleton by skeleton.

A message shaped like one decoded before is recognised by its constant bytes and read with one
gather; a skeleton of a known shape by its block plan; anything else by the field reader, which
refuses what breaks DESIGN.md's conventions (duplicate or negative ids, a link whose id is not
its child's) with ``CodecError``.
"""

from __future__ import annotations

import hashlib

import numpy as np

from hiros_core.cdr import HEADER_SIZE, CdrReader, Plan
from hiros_core.codec.fields import NS, join_ns
from hiros_core.codec.group_plans import (
    BOX_FLOATS,
    CONFIDENCE_STRUCT,
    GROUP_PLAN_CAPACITY,
    GROUP_READINGS,
    HEAD_STRUCT,
    LEAD,
    MAXES_STRUCT,
    SKELETON_PLANS,
    STAMP_STRUCT,
    GroupReading,
    SkeletonShape,
    build_skeleton_plan,
    group_reading,
    skeleton_key,
)
from hiros_core.errors import LayoutError
from hiros_core.layouts import AZURE_KINECT, KINECT_V2, Layout
from hiros_core.limits import check_skeleton_group
from hiros_core.model import BOX_WIDTH, STATE_WIDTH, Skeleton, SkeletonGroup, SkeletonRows

_MAX_DENSE_ID = 4096  # dense rows by id: larger ids would allocate absurd arrays
_HEAD = np.dtype([("id", "<i4"), ("sec", "<i4"), ("nanosec", "<u4")])
_MAXES = np.dtype([("max_markers", "<u4"), ("max_links", "<u4")])
_MIN_SKELETON_BYTES = 4 + 8 + 5 + 8 + 8 * BOX_FLOATS + 8  # id, time, "", maxes, box, 2 counts
_GROUP_READING_CANDIDATES = 8


def decode_group(data: bytes | bytearray | memoryview) -> SkeletonGroup:
    """The model of a ``SkeletonGroup`` from CDR bytes; raises CodecError on bad bytes.

    A message shaped like one decoded before (same frames, people's layouts and present
    markers and links) is recognised by comparing its constant bytes as 8-byte words, and
    read with one gather of all its floats (absent rows read a NaN scratch row); the
    skeletons' rows are views into that one array. Other messages are read skeleton by
    skeleton and teach the shape.
    """
    check_skeleton_group(data)  # past hiros_core.limits: refused before anything is made
    size = len(data) if isinstance(data, bytes) else memoryview(data).nbytes
    readings = GROUP_READINGS.get(size)
    if readings:
        raw = np.frombuffer(data, dtype=np.uint8)
        buffer = np.empty(readings[0].words.size * 8, dtype=np.uint8)
        buffer[LEAD : LEAD + size] = raw
        words = buffer.view("<u8")
        for reading in readings:
            differ = np.bitwise_xor(words, reading.words)
            differ &= reading.mask
            if not differ.any():
                return _group_from_reading(reading, buffer)
    group = _decode_group_by_skeleton(data)
    reading = group_reading(group, size)
    if reading is not None:
        found = GROUP_READINGS.setdefault(size, [])
        found.insert(0, reading)
        del found[_GROUP_READING_CANDIDATES:]
        if len(GROUP_READINGS) > GROUP_PLAN_CAPACITY:
            GROUP_READINGS.clear()
    return group


def _group_from_reading(reading: GroupReading, buffer: np.ndarray) -> SkeletonGroup:
    plan = reading.plan
    floats = buffer[LEAD + HEADER_SIZE :].view("<f8")
    floats[reading.scratch : reading.scratch + STATE_WIDTH] = np.nan
    if reading.stack is not None:
        return _stacked_group(reading, buffer, floats)
    values = floats[plan.floats]
    sec, nanosec = STAMP_STRUCT.unpack_from(buffer, plan.stamp_at)
    skeletons = []
    for (head_at, maxes_at, box_at), (layout, frame, present, link_present, start) in zip(
        plan.fields, reading.skeletons, strict=True
    ):
        skeleton_id, src_sec, src_nanosec = HEAD_STRUCT.unpack_from(buffer, head_at)
        max_markers, max_links = MAXES_STRUCT.unpack_from(buffer, maxes_at)
        (confidence,) = CONFIDENCE_STRUCT.unpack_from(buffer, box_at)
        markers_at = start + BOX_WIDTH
        links_at = markers_at + layout.n_joints * STATE_WIDTH
        skeletons.append(
            Skeleton(
                skeleton_id, src_sec * NS + src_nanosec, frame, layout,
                values[markers_at:links_at].reshape(-1, STATE_WIDTH),
                values[links_at : links_at + layout.n_links * STATE_WIDTH].reshape(
                    -1, STATE_WIDTH
                ),
                present.copy(), link_present.copy(), confidence,
                values[start:markers_at], max_markers, max_links,
            )
        )  # fmt: skip
    return SkeletonGroup(sec * NS + nanosec, reading.frame_id, skeletons)


def _stacked_group(reading: GroupReading, buffer: np.ndarray, floats: np.ndarray) -> SkeletonGroup:
    """A group of one layout, its skeletons the rows of one ``SkeletonRows`` (one gather)."""
    plan, stack = reading.plan, reading.stack
    assert stack is not None
    values = plan.packer.unpack(buffer[plan.field_index].tobytes())
    n_people = len(stack.frames)
    rows = floats[stack.floats]
    boxes_end = n_people * BOX_WIDTH
    markers_end = boxes_end + stack.marker_present.size * STATE_WIDTH
    skeletons = SkeletonRows(
        rows[boxes_end:markers_end].reshape(n_people, -1, STATE_WIDTH),
        stack.marker_present.copy(),
        rows[markers_end:].reshape(n_people, -1, STATE_WIDTH),
        stack.link_present.copy(),
        rows[:boxes_end].reshape(n_people, BOX_WIDTH),
    ).skeletons(
        values[2::6],
        [sec * NS + nanosec for sec, nanosec in zip(values[3::6], values[4::6], strict=True)],
        stack.frames,
        stack.layout,
        values[7::6],
        max_sizes=list(zip(values[5::6], values[6::6], strict=True)),
    )
    return SkeletonGroup(values[0] * NS + values[1], reading.frame_id, skeletons)


def _decode_group_by_skeleton(data: bytes | bytearray | memoryview) -> SkeletonGroup:
    """``decode_group`` through per-skeleton block plans (or the field reader)."""
    reader = CdrReader(data, "hiros_skeleton_msgs/SkeletonGroup")
    raw = np.frombuffer(data, dtype=np.uint8)
    stamp_sec, stamp_nanosec = reader.i32(), reader.u32()
    frame_id = reader.string()
    count = reader.count(_MIN_SKELETON_BYTES)
    skeletons = []
    for _ in range(count):
        reader.align(4)
        phase = (reader.pos - HEADER_SIZE) % 8
        plan = SKELETON_PLANS.find_at(raw, reader.pos, phase)
        if plan is None:
            skeleton = _parse_skeleton(reader)
            SKELETON_PLANS.put(
                skeleton_key(skeleton, phase), build_skeleton_plan(skeleton, phase), phase
            )
        else:
            skeleton = _skeleton_from_block(plan, raw, reader.pos)
            reader.pos += plan.size
        skeletons.append(skeleton)
    reader.done()
    return SkeletonGroup(stamp_sec * NS + stamp_nanosec, frame_id, skeletons)


def _skeleton_from_block(plan: Plan, raw: np.ndarray, start: int) -> Skeleton:
    shape: SkeletonShape = plan.meta  # type: ignore[assignment]
    values = plan.gather_all(raw, start)
    head = values["head"].view(_HEAD).ravel()
    maxes = values["maxes"].view(_MAXES).ravel()
    box = values["box"].view("<f8").ravel()
    skeleton = Skeleton.empty(shape.layout, skeleton_id=int(head["id"][0]))
    skeleton.src_time_ns = int(join_ns(head)[0])
    skeleton.src_frame = shape.src_frame
    skeleton.max_markers = int(maxes["max_markers"][0])
    skeleton.max_links = int(maxes["max_links"][0])
    skeleton.confidence = float(box[0])
    skeleton.bounding_box = box[1:].copy()
    if "markers" in values:
        skeleton.markers[shape.marker_ids] = values["markers"].view("<f8")
    if "links" in values:
        skeleton.links[shape.link_ids] = values["links"].view("<f8")
    skeleton.marker_present[shape.marker_ids] = True
    skeleton.link_present[shape.link_ids] = True
    return skeleton


def _parse_skeleton(reader: CdrReader) -> Skeleton:
    skeleton_id = reader.i32()
    src_time_ns = reader.i32() * NS + reader.u32()
    src_frame = reader.string()
    max_markers, max_links = reader.u32(), reader.u32()
    box = reader.floats(BOX_FLOATS)
    markers: dict[int, tuple[str, np.ndarray]] = {}
    for _ in range(reader.count(8 + 8 * STATE_WIDTH)):
        marker_id, name = reader.i32(), reader.string()
        if marker_id in markers:
            reader.fail(f"skeleton {skeleton_id} repeats marker id {marker_id}")
        markers[marker_id] = (name, reader.floats(STATE_WIDTH))
    links: dict[int, tuple[str, int, np.ndarray]] = {}
    for _ in range(reader.count(16 + 8 * STATE_WIDTH)):
        link_id, name, parent, child = reader.i32(), reader.string(), reader.i32(), reader.i32()
        if link_id != child:
            reader.fail(f"link {link_id} has child marker {child}; a link's id must be its child's")
        if link_id in links:
            reader.fail(f"skeleton {skeleton_id} repeats link id {link_id}")
        links[link_id] = (name, parent, reader.floats(STATE_WIDTH))
    layout = _layout_for(reader, markers, links)
    skeleton = Skeleton.empty(layout, skeleton_id=skeleton_id, src_frame=src_frame)
    skeleton.src_time_ns = src_time_ns
    skeleton.max_markers, skeleton.max_links = max_markers, max_links
    skeleton.confidence, skeleton.bounding_box = float(box[0]), box[1:]
    for marker_id, (_, row) in markers.items():
        skeleton.markers[marker_id] = row
        skeleton.marker_present[marker_id] = True
    for link_id, (_, _, row) in links.items():
        skeleton.links[link_id] = row
        skeleton.link_present[link_id] = True
    return skeleton


_DECODED_LAYOUTS: dict[tuple, Layout] = {}


def _layout_for(
    reader: CdrReader,
    markers: dict[int, tuple[str, np.ndarray]],
    links: dict[int, tuple[str, int, np.ndarray]],
) -> Layout:
    """The built-in layout these names fit, else one made from the message (cached)."""
    ids = list(markers) + list(links)
    if ids and (min(ids) < 0 or max(ids) >= _MAX_DENSE_ID):
        reader.fail(f"marker/link id outside 0..{_MAX_DENSE_ID - 1}")
    for layout in (AZURE_KINECT, KINECT_V2):
        if _fits(layout, markers, links):
            return layout
    key = (
        tuple((i, m[0]) for i, m in sorted(markers.items())),
        tuple((i, m[0], m[1]) for i, m in sorted(links.items())),
    )
    if key not in _DECODED_LAYOUTS:
        size = max(ids, default=-1) + 1
        names = [markers[i][0] if i in markers else f"joint{i}" for i in range(size)]
        parents = [links[i][1] if i in links else -1 for i in range(size)]
        labels = [links[i][0] if i in links else "" for i in range(size)]
        try:
            _DECODED_LAYOUTS[key] = Layout(
                _decoded_name(key, size), tuple(names), tuple(parents), tuple(labels)
            )
        except LayoutError as exc:
            reader.fail(str(exc))
    return _DECODED_LAYOUTS[key]


def _decoded_name(key: tuple, size: int) -> str:
    """A name of its own for each decoded layout, the same in every run.

    The stages keep per-layout state (track memories, kernel constants, filter batches) by
    layout name; two decoded layouts of one name, e.g. 3 and 32 joints, used to share that
    state, and the optimizer's compiled kernels then wrote past their arrays (a segfault).
    """
    digest = hashlib.blake2b(repr(key).encode(), digest_size=4).hexdigest()
    return f"decoded_{size}_{digest}"


def _fits(
    layout: Layout,
    markers: dict[int, tuple[str, np.ndarray]],
    links: dict[int, tuple[str, int, np.ndarray]],
) -> bool:
    n = layout.n_joints
    return all(i < n and layout.joint_names[i] == m[0] for i, m in markers.items()) and all(
        i < n and layout.link_names[i] == name and layout.parents[i] == parent
        for i, (name, parent, _) in links.items()
    )
