"""CDR bytes -> SkeletonGroup: every message our plans reproduce is read by one gather.

A message shaped like one decoded before is recognised by its constant bytes and its values
are read with one gather. A new shape is learnt first: the message is walked skeleton by
skeleton, a skeleton of a known shape recognised by its block plan and any other read by the
field reader, which refuses what breaks DESIGN.md's conventions (duplicate or negative ids, a
link whose id is not its child's) with ``CodecError``; then it is read like a known one. A
message no plan reproduces (markers in another order than their ids, as other tools may
write them; a string cut at an embedded NUL) is what the field reader read.
"""

from __future__ import annotations

import hashlib

import numpy as np

from hiros_core.cdr import HEADER_SIZE, CdrReader
from hiros_core.codec.fields import NS
from hiros_core.codec.group_plans import (
    BOX_FLOATS,
    GROUP_PLAN_CAPACITY,
    GROUP_READINGS,
    LEAD,
    SKELETON_PLANS,
    GroupReading,
    SkeletonShape,
    StackReading,
    build_skeleton_plan,
    group_reading,
    skeleton_key,
)
from hiros_core.errors import LayoutError
from hiros_core.layouts import AZURE_KINECT, KINECT_V2, Layout
from hiros_core.limits import check_skeleton_group
from hiros_core.model import BOX_WIDTH, STATE_WIDTH, Skeleton, SkeletonGroup, SkeletonRows

_MAX_DENSE_ID = 4096  # dense rows by id: larger ids would allocate absurd arrays
_MIN_SKELETON_BYTES = 4 + 8 + 5 + 8 + 8 * BOX_FLOATS + 8  # id, time, "", maxes, box, 2 counts
_GROUP_READING_CANDIDATES = 8


def decode_group(data: bytes | bytearray | memoryview) -> SkeletonGroup:
    """The model of a ``SkeletonGroup`` from CDR bytes; raises CodecError on bad bytes.

    A message shaped like one decoded before (same frames, people's layouts and present
    markers and links) is recognised by comparing its constant bytes as 8-byte words, and
    read with one gather of all its floats (absent rows read a NaN scratch row): the
    skeletons of each layout are the rows of one ``SkeletonRows``, views of that gather.
    A new shape is learnt from the message first, then read so.
    """
    check_skeleton_group(data)  # past hiros_core.limits: refused before anything is made
    raw = np.frombuffer(data, dtype=np.uint8)
    known = GROUP_READINGS.get(raw.size)
    if known:
        buffer = _aligned(raw, known[0])
        for reading in known:
            if _matches(reading, buffer):
                return _read(reading, buffer)
    group, complete = _walk(data, raw, recognise=True)
    reading = group_reading(group, raw.size)
    if reading is not None:
        buffer = _aligned(raw, reading)
        if _matches(reading, buffer):
            _remember(reading, raw.size)
            return _read(reading, buffer)
    # no plan reproduces these bytes: the field reader's values are the message's
    return group if complete else _walk(data, raw, recognise=False)[0]


def _aligned(raw: np.ndarray, reading: GroupReading) -> np.ndarray:
    """The message's bytes after ``LEAD`` spare bytes, its payload 8-byte aligned in memory.

    As long as the reading's template: its scratch row lies past the message end.
    """
    buffer = np.empty(reading.words.size * 8, dtype=np.uint8)
    buffer[LEAD : LEAD + raw.size] = raw
    return buffer


def _matches(reading: GroupReading, buffer: np.ndarray) -> bool:
    """Whether the message in ``buffer`` has the reading's constant bytes."""
    differ = np.bitwise_xor(buffer.view("<u8"), reading.words)
    differ &= reading.mask
    return not differ.any()


def _remember(reading: GroupReading, size: int) -> None:
    """Keep the reading among the most recent few of its message size."""
    found = GROUP_READINGS.setdefault(size, [])
    found.insert(0, reading)
    del found[_GROUP_READING_CANDIDATES:]
    if len(GROUP_READINGS) > GROUP_PLAN_CAPACITY:
        GROUP_READINGS.clear()


def _read(reading: GroupReading, buffer: np.ndarray) -> SkeletonGroup:
    """The group in ``buffer`` by the reading: one gather, one ``SkeletonRows`` per layout."""
    plan = reading.plan
    floats = buffer[LEAD + HEADER_SIZE :].view("<f8")
    floats[reading.scratch : reading.scratch + STATE_WIDTH] = np.nan
    values = plan.packer.unpack(buffer[plan.field_index].tobytes())
    # the stamp, then per skeleton: id, source sec and nanosec, max_markers, max_links, conf.
    fields = [values[at : at + 6] for at in range(2, len(values), 6)]
    skeletons: list[Skeleton] = [None] * len(fields)  # type: ignore[list-item]
    for stack in reading.stacks:
        for person, skeleton in zip(
            stack.people, _stack_skeletons(stack, floats, fields), strict=True
        ):
            skeletons[person] = skeleton
    return SkeletonGroup(values[0] * NS + values[1], reading.frame_id, skeletons)


def _stack_skeletons(
    stack: StackReading, floats: np.ndarray, fields: list[tuple]
) -> list[Skeleton]:
    """The skeletons of one layout: rows of one ``SkeletonRows`` gathered from ``floats``."""
    n_people = len(stack.people)
    rows = floats[stack.floats]
    boxes_end = n_people * BOX_WIDTH
    markers_end = boxes_end + stack.marker_present.size * STATE_WIDTH
    people = [fields[p] for p in stack.people]
    return SkeletonRows(
        rows[boxes_end:markers_end].reshape(n_people, -1, STATE_WIDTH),
        stack.marker_present.copy(),
        rows[markers_end:].reshape(n_people, -1, STATE_WIDTH),
        stack.link_present.copy(),
        rows[:boxes_end].reshape(n_people, BOX_WIDTH),
    ).skeletons(
        [f[0] for f in people],
        [f[1] * NS + f[2] for f in people],
        stack.frames,
        stack.layout,
        [f[5] for f in people],
        max_sizes=[(f[3], f[4]) for f in people],
    )


def _walk(
    data: bytes | bytearray | memoryview, raw: np.ndarray, *, recognise: bool
) -> tuple[SkeletonGroup, bool]:
    """The group skeleton by skeleton, and whether every skeleton carries its values.

    With ``recognise``, a skeleton whose block a cached plan recognises is only its shape
    (frame, layout, present ids: what a reading needs, which gathers the values); any other
    is read by the field reader, which checks it, and its block plan is cached.
    """
    reader = CdrReader(data, "hiros_skeleton_msgs/SkeletonGroup")
    stamp_sec, stamp_nanosec = reader.i32(), reader.u32()
    frame_id = reader.string()
    count = reader.count(_MIN_SKELETON_BYTES)
    skeletons, complete = [], True
    for _ in range(count):
        reader.align(4)
        phase = (reader.pos - HEADER_SIZE) % 8
        plan = SKELETON_PLANS.find_at(raw, reader.pos, phase) if recognise else None
        if plan is None:
            skeleton = _parse_skeleton(reader)
            SKELETON_PLANS.put(
                skeleton_key(skeleton, phase), build_skeleton_plan(skeleton, phase), phase
            )
        else:
            skeleton = _shape(plan.meta)  # type: ignore[arg-type]
            complete = False
            reader.pos += plan.size
        skeletons.append(skeleton)
    reader.done()
    return SkeletonGroup(stamp_sec * NS + stamp_nanosec, frame_id, skeletons), complete


def _shape(shape: SkeletonShape) -> Skeleton:
    """A skeleton of the block plan's shape, with no values."""
    skeleton = Skeleton.empty(shape.layout, src_frame=shape.src_frame)
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
