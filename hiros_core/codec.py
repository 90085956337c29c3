"""Fast CDR codec: SkeletonGroup and MarkerArray bytes <-> the numpy model, no rclpy objects.

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
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from hiros_core.cdr import (
    HEADER_SIZE,
    BlockPlans,
    CdrReader,
    Plan,
    PlanBuilder,
    PlanCache,
    aligned_copy,
)
from hiros_core.errors import CodecError, LayoutError
from hiros_core.layouts import AZURE_KINECT, KINECT_V2, Layout
from hiros_core.limits import check_marker_array, check_skeleton_group
from hiros_core.model import (
    BOX_WIDTH,
    STATE_WIDTH,
    Skeleton,
    SkeletonGroup,
    SkeletonRows,
    shared_stack,
    warm_up_group,
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

_NS = 1_000_000_000
_MAX_DENSE_ID = 4096  # dense rows by id: larger ids would allocate absurd arrays
_TIME = np.dtype([("sec", "<i4"), ("nanosec", "<u4")])
_HEAD = np.dtype([("id", "<i4"), ("sec", "<i4"), ("nanosec", "<u4")])
_MAXES = np.dtype([("max_markers", "<u4"), ("max_links", "<u4")])
_HEAD_STRUCT = struct.Struct("<iiI")
_STAMP_STRUCT = struct.Struct("<iI")
_MAXES_STRUCT = struct.Struct("<II")
_CONFIDENCE_STRUCT = struct.Struct("<d")
_ITA = np.dtype([("id", "<i4"), ("type", "<i4"), ("action", "<i4")])
_ROW_BYTES = STATE_WIDTH * 8
_BOX, _MARKERS, _LINKS = 0, 1, 2  # sources of a plan's float runs (``fill.fill_runs``)
_BOX_FLOATS = 1 + BOX_WIDTH  # skeleton confidence + bounding box
_MIN_SKELETON_BYTES = 4 + 8 + 5 + 8 + 8 * _BOX_FLOATS + 8  # id, time, "", maxes, box, 2 counts


def _split_ns(stamps_ns: np.ndarray, what: str) -> np.ndarray:
    """Integer nanoseconds to (sec, nanosec) records; refuses stamps outside int32 seconds."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    sec, nanosec = np.divmod(stamps, _NS)
    if sec.size and (sec.min() < -(2**31) or sec.max() >= 2**31):
        msg = f"{what}: a stamp is outside the int32 seconds range of builtin_interfaces/Time"
        raise CodecError(msg)
    out = np.empty(stamps.shape, dtype=_TIME)
    out["sec"], out["nanosec"] = sec, nanosec
    return out


def _c_string(text: str) -> str:
    """What a string becomes in CDR: rclpy ends it at the first NUL."""
    return text.split("\x00", 1)[0]


def _join_ns(times: np.ndarray) -> np.ndarray:
    return times["sec"].astype(np.int64) * _NS + times["nanosec"].astype(np.int64)


def _checked(values: list[int], dtype: str, what: str) -> np.ndarray:
    info = np.iinfo(dtype)
    if values and (min(values) < info.min or max(values) > info.max):
        msg = f"{what}: value out of range for {np.dtype(dtype).name}"
        raise CodecError(msg)
    return np.asarray(values, dtype=dtype)


# --------------------------------------------------------------------------- SkeletonGroup


@dataclass(frozen=True)
class _SkeletonShape:
    """What a block plan fixes about one skeleton: frame, layout and which ids it carries.

    For encoding, where its fields go in the block: byte offsets of the id/stamp and of the
    two max fields, and the float64 positions (in 8-byte units from the payload start, less
    the block's ``(start - phase) / 8``) of the confidence + box, marker rows and link rows.
    """

    src_frame: str
    layout: Layout
    marker_ids: np.ndarray
    link_ids: np.ndarray
    head_at: int = 0
    maxes_at: int = 0
    floats: tuple[np.ndarray, ...] = ()


# Each skeleton is its own block (plans reused whatever the other people in the group), so a
# tracker output mixing cameras and people costs no more plans than the cameras' own frames.
_SKELETON_PLANS = BlockPlans()
_GROUP_HEADER = PlanCache(capacity=64)


def clear_plan_caches() -> None:
    """Forget every cached plan (they are rebuilt on demand; for tests and memory)."""
    for cache in (_SKELETON_PLANS, _GROUP_HEADER, _MARKER_PLANS):
        cache.by_key.clear()
    _GROUP_PLANS.clear()
    _STACK_PLANS.clear()
    _GROUP_READINGS.clear()
    _SKELETON_PLANS.by_phase.clear()
    _GROUP_HEADER.by_size.clear()
    _MARKER_PLANS.by_size.clear()


def _skeleton_key(skeleton: Skeleton, phase: int) -> tuple:
    return (
        skeleton.src_frame,
        skeleton.layout,
        skeleton.marker_present.tobytes(),
        skeleton.link_present.tobytes(),
        phase,
    )


def _build_skeleton_plan(skeleton: Skeleton, payload_offset: int) -> Plan:
    builder = PlanBuilder(payload_offset)
    layout = skeleton.layout
    marker_ids = np.flatnonzero(skeleton.marker_present)
    link_ids = np.flatnonzero(skeleton.link_present)
    builder.slot("head", 12, 4)
    builder.string(skeleton.src_frame)
    builder.slot("maxes", 8, 4)
    builder.slot("box", _BOX_FLOATS * 8, 8)
    builder.u32(marker_ids.size)
    for marker_id in marker_ids:
        builder.i32(int(marker_id))
        builder.string(layout.joint_names[marker_id])
        builder.slot("markers", _ROW_BYTES, 8)
    builder.u32(link_ids.size)
    for link_id in link_ids:
        builder.i32(int(link_id))
        builder.string(layout.link_names[link_id])
        builder.i32(layout.parents[link_id])
        builder.i32(int(link_id))
        builder.slot("links", _ROW_BYTES, 8)

    def floats(kind: str, width: int) -> np.ndarray:
        offsets = np.asarray(builder.slots.get(kind, []), dtype=np.intp) + payload_offset
        return (offsets[:, None] // 8 + np.arange(width)).ravel()

    return builder.build(
        _SkeletonShape(
            _c_string(skeleton.src_frame),
            layout,
            marker_ids,
            link_ids,
            builder.slots["head"][0],
            builder.slots["maxes"][0],
            (
                floats("box", _BOX_FLOATS),
                floats("markers", STATE_WIDTH),
                floats("links", STATE_WIDTH),
            ),
        )
    )


def _rows(arrays: list[np.ndarray], width: int) -> np.ndarray:
    return np.concatenate(arrays) if arrays else np.empty((0, width))


def _group_header(group: SkeletonGroup) -> Plan:
    key = (group.frame_id, len(group.skeletons))
    plan = _GROUP_HEADER.get(key)
    if plan is None:
        builder = PlanBuilder()
        builder.slot("stamp", 8, 4)
        builder.string(group.frame_id)
        builder.u32(len(group.skeletons))
        plan = _GROUP_HEADER.put(key, builder.build())
    return plan


@dataclass(frozen=True)
class _GroupPlan:
    """A whole group's encoding: template, and where each skeleton's values go.

    ``floats`` indexes a float64 view of the payload for the concatenation, per skeleton, of
    its bounding box ``(22,)``, all ``J`` marker rows and all ``L`` link rows: rows the
    skeleton does not carry point into a scratch row past the message end, so encoding
    needs no per-skeleton selection of present rows. The template starts with ``_LEAD``
    spare bytes so that the payload, and so the float view, is 8-byte aligned in memory
    (numpy scatters into unaligned views several times slower).
    """

    template: np.ndarray
    size: int
    stamp_at: int
    fields: tuple[tuple[int, int, int], ...]  # per skeleton: head, maxes, confidence offsets
    floats: np.ndarray
    packer: struct.Struct  # the group's integer fields and confidences, in ``field_runs`` order
    field_index: np.ndarray  # template byte of each packed byte (the numpy encoder's scatter)
    field_runs: np.ndarray  # (F, 3) message offset, packed offset, bytes (the compiled copy)
    runs: np.ndarray  # (R, 4) message offset, source, float offset in the values, floats
    stack_runs: np.ndarray | None  # ``runs`` with offsets in SkeletonRows fields (same sizes)
    layouts: tuple[Layout, ...] = ()  # kept alive: encode_group's cache keys hold their ids
    message: np.ndarray = field(init=False)  # the template's message bytes (no lead, scratch)

    def __post_init__(self) -> None:
        object.__setattr__(self, "message", self.template[_LEAD : _LEAD + self.size])


@dataclass(frozen=True)
class _GroupReading:
    """What decoding needs beyond a ``_GroupPlan``: how to recognise the message and rebuild it.

    ``words``/``mask``: the template and its constant bytes as 8-byte words (``cdr.Plan``'s
    ``matches_aligned`` idea over the whole group); ``skeletons``: per skeleton its layout,
    source frame, presence masks and where its box, marker and link rows start in the
    gathered floats.
    """

    plan: _GroupPlan
    frame_id: str
    words: np.ndarray
    mask: np.ndarray
    scratch: int  # float64 position of the scratch row (filled with NaN when decoding)
    skeletons: tuple[tuple[Layout, str, np.ndarray, np.ndarray, int], ...]
    stack: _StackReading | None = None  # when every skeleton has one layout


class _StackReading(NamedTuple):
    """How a group of one layout is decoded as one ``SkeletonRows``.

    ``floats``: the plan's float indices reordered field by field (every box, then every
    skeleton's marker rows, then every link rows), so one gather gives the three fields as
    contiguous blocks; the presence masks and source frames of the skeletons.
    """

    layout: Layout
    floats: np.ndarray
    marker_present: np.ndarray  # (P, J)
    link_present: np.ndarray  # (P, L)
    frames: list[str]


_GROUP_READINGS: dict[int, list[_GroupReading]] = {}  # by message size, most recent first
_GROUP_READING_CANDIDATES = 8


def _group_reading(group: SkeletonGroup, size: int) -> _GroupReading | None:
    """The reading of messages shaped like ``group`` (just decoded from ``size`` bytes)."""
    keys = [
        (s.src_frame, s.layout, s.marker_present.tobytes(), s.link_present.tobytes())
        for s in group.skeletons
    ]
    header = _group_header(group)
    offset = header.size - HEADER_SIZE
    blocks = []
    for skeleton, key in zip(group.skeletons, keys, strict=True):
        phase = offset % 8
        plan = _SKELETON_PLANS.get((*key, phase)) or _SKELETON_PLANS.put(
            (*key, phase), _build_skeleton_plan(skeleton, phase), phase
        )
        blocks.append((offset, plan))
        offset += plan.size
    if offset + HEADER_SIZE != size:
        return None  # the message is laid out otherwise (never met: the reader would fail)
    phased = [(*key, start % 8) for key, (start, _) in zip(keys, blocks, strict=True)]
    plan = _build_group_plan(group, phased)
    constant = [header.constant]
    constant += [block.constant + start + HEADER_SIZE for start, block in blocks]
    mask = np.zeros(plan.template.size + (-plan.template.size) % 8, dtype=np.uint8)
    mask[np.concatenate(constant) + _LEAD] = 0xFF
    words = np.zeros_like(mask)
    words[: plan.template.size] = plan.template
    skeletons, start = [], 0
    for skeleton in group.skeletons:
        n_markers, n_links = skeleton.layout.n_joints, skeleton.layout.n_links
        skeletons.append(
            (
                skeleton.layout,
                skeleton.src_frame,
                skeleton.marker_present.copy(),
                skeleton.link_present.copy(),
                start,
            )
        )
        start += BOX_WIDTH + (n_markers + n_links) * STATE_WIDTH
    return _GroupReading(
        plan,
        group.frame_id,
        words.view("<u8"),
        mask.view("<u8"),
        (offset + (-offset) % 8) // 8,  # as _build_group_plan places it
        tuple(skeletons),
        _stack_reading(group, plan),
    )


def _stack_reading(group: SkeletonGroup, plan: _GroupPlan) -> _StackReading | None:
    """The stack decoding of messages shaped like ``group`` (None: mixed layouts, or none)."""
    skeletons = group.skeletons
    if not skeletons or any(s.layout is not skeletons[0].layout for s in skeletons):
        return None
    layout = skeletons[0].layout
    marker_floats = layout.n_joints * STATE_WIDTH
    per_person = plan.floats.reshape(len(skeletons), -1)
    fields = np.split(per_person, [BOX_WIDTH, BOX_WIDTH + marker_floats], axis=1)
    return _StackReading(
        layout,
        np.concatenate([field.ravel() for field in fields]),
        np.array([s.marker_present for s in skeletons]),
        np.array([s.link_present for s in skeletons]),
        [s.src_frame for s in skeletons],
    )


_GROUP_PLANS: dict[tuple, _GroupPlan] = {}
_GROUP_PLAN_CAPACITY = 256
_LEAD = 8 - HEADER_SIZE  # template bytes before the CDR header: aligns the payload


def _build_group_plan(group: SkeletonGroup, keys: list[tuple]) -> _GroupPlan:
    header = _group_header(group)
    offset = header.size - HEADER_SIZE
    templates = [np.zeros(_LEAD, dtype=np.uint8), header.template]
    fields, indices, runs = [], [], []
    stamp_at = int(header.slots["stamp"][0]) + _LEAD
    packed = [(stamp_at, _STAMP_STRUCT)]
    blocks = []
    for skeleton, key in zip(group.skeletons, keys, strict=True):
        phase = offset % 8
        plan = _SKELETON_PLANS.get(key) or _SKELETON_PLANS.put(
            key, _build_skeleton_plan(skeleton, phase), phase
        )
        blocks.append((offset, phase, plan, skeleton))
        templates.append(plan.template)
        offset += plan.size
    size = offset + HEADER_SIZE
    scratch = (-(offset)) % 8 + offset  # payload offset of the scratch row, 8-aligned
    templates.append(np.zeros(scratch - offset + _ROW_BYTES, dtype=np.uint8))
    dump = np.arange(STATE_WIDTH) + scratch // 8
    values_at = 0  # where the skeleton's box, marker and link rows start in the values
    for person, (start, phase, plan, skeleton) in enumerate(blocks):
        shape: _SkeletonShape = plan.meta  # type: ignore[assignment]
        at = start + HEADER_SIZE + _LEAD
        box_at = int(plan.slots["box"][0]) + at
        fields.append((at + shape.head_at, at + shape.maxes_at, box_at))
        packed += [(at + shape.head_at, _HEAD_STRUCT), (at + shape.maxes_at, _MAXES_STRUCT)]
        packed.append((box_at, _CONFIDENCE_STRUCT))
        shift = (start - phase) // 8
        box_index, marker_index, link_index = shape.floats
        markers = np.tile(dump, (skeleton.layout.n_joints, 1))
        markers[shape.marker_ids] = (marker_index + shift).reshape(-1, STATE_WIDTH)
        links = np.tile(dump, (skeleton.layout.n_links, 1))
        links[shape.link_ids] = (link_index + shift).reshape(-1, STATE_WIDTH)
        indices += [box_index[1:] + shift, markers.ravel(), links.ravel()]
        runs += _value_runs(
            box_index[1] + shift, markers[:, 0], links[:, 0], dump[0], values_at, person
        )
        values_at += BOX_WIDTH + (skeleton.layout.n_joints + skeleton.layout.n_links) * STATE_WIDTH
    floats = np.concatenate(indices) if indices else np.empty(0, dtype=np.intp)
    all_runs = np.array(runs, dtype=np.int64).reshape(-1, 5)
    stackable = len({(s.layout.n_joints, s.layout.n_links) for s in group.skeletons}) <= 1
    return _GroupPlan(
        np.concatenate(templates),
        size,
        stamp_at,
        tuple(fields),
        floats,
        struct.Struct("<" + "".join(kind.format[1:] for _, kind in packed)),
        np.concatenate([np.arange(at, at + kind.size) for at, kind in packed]),
        _field_runs(packed),
        np.ascontiguousarray(all_runs[:, :4]),
        np.ascontiguousarray(all_runs[:, [0, 1, 4, 3]]) if stackable else None,
        tuple(skeleton.layout for skeleton in group.skeletons),
    )


def _field_runs(packed: list[tuple[int, struct.Struct]]) -> np.ndarray:
    """``(F, 3)`` message offset, packed offset and length of each packed field."""
    runs, at = [], 0
    for template_at, kind in packed:
        runs.append((template_at - _LEAD, at, kind.size))
        at += kind.size
    return np.array(runs, dtype=np.int64).reshape(-1, 3)


def _value_runs(  # noqa: PLR0917 - one skeleton's positions, all needed
    box: int, markers: np.ndarray, links: np.ndarray, dump: int, values_at: int, person: int
) -> list[tuple[int, int, int, int, int]]:
    """One skeleton's float runs (present rows only), as tuples of five.

    Each run: message offset, source, values offset, floats, stack offset. ``box``,
    ``markers`` and ``links`` are payload float positions of the box and of each row's first
    float (``dump`` for rows the skeleton does not carry). ``source`` says which of the
    box, marker or link rows a run copies (``_BOX``, ``_MARKERS``, ``_LINKS``); the values
    offset is where the run starts in the concatenated values of ``encode_group_into``, the
    stack offset where it starts in that source's ``SkeletonRows`` field (``person`` being the
    skeleton's row there).
    """
    runs = [(HEADER_SIZE + 8 * int(box), _BOX, values_at, BOX_WIDTH, person * BOX_WIDTH)]
    at = values_at + BOX_WIDTH
    for source, rows in ((_MARKERS, markers), (_LINKS, links)):
        stack_at = person * rows.size * STATE_WIDTH
        for row, first in enumerate(rows.tolist()):
            if first != dump:
                offset = row * STATE_WIDTH
                runs.append(
                    (HEADER_SIZE + 8 * first, source, at + offset, STATE_WIDTH, stack_at + offset)
                )
        at += rows.size * STATE_WIDTH
    return runs


def encode_group(group: SkeletonGroup) -> bytes:
    """CDR bytes of ``hiros_skeleton_msgs/msg/SkeletonGroup`` for the model ``group``.

    The group's plan (cached by the shapes of its skeletons) gives one template for the whole
    message, one struct for its integer fields and one index for all its floats: encoding is
    a template copy, one pack and one scatter of every skeleton's rows.
    """
    out = None

    def space(size: int) -> tuple[np.ndarray, int]:
        nonlocal out
        out = np.empty(size, dtype=np.uint8)
        return out, 0

    encode_group_into(group, space)
    return out.tobytes()  # type: ignore[union-attr]


def warm_up() -> None:
    """Load the compiled encoder now (numba's disk cache, ~15 ms), not on the first group.

    A writer or a node would otherwise load it while its clock runs. Cheap after the first
    call (numba keeps what it loaded).
    """
    encode_group(warm_up_group())


def encode_group_into(group: SkeletonGroup, space: Callable[[int], tuple[np.ndarray, int]]) -> int:
    """Encode ``group`` where ``space(size)`` says (uint8 array, offset); returns the size.

    For writers that keep messages in a buffer of their own (``RecordingWriter`` writes
    straight into its MCAP chunk): no ``bytes`` object is made. Nothing is written when the
    group cannot be encoded (``CodecError`` before ``space`` is called). A group whose
    skeletons are the rows of one ``SkeletonRows`` stack (what the stages make) is copied
    from that stack, keyed by it, with no per-skeleton array work. Float64 values (all the
    model makes) are copied by the compiled ``fill.fill_runs``, others by its numpy form.
    """
    skeletons = group.skeletons
    stack = shared_stack(skeletons) if skeletons else None
    if stack is not None:
        plan = _stack_plan(group, stack)
        if plan is not None:
            packed = _pack(plan, group)
            out, at = space(plan.size)
            _fill_compiled(out, at, plan, packed, stack)
            return plan.size
    plan = _plan_of(group)
    packed = _pack(plan, group)
    values = np.concatenate(
        [a for s in skeletons for a in (s.bounding_box, s.markers, s.links)], axis=None
    ) if skeletons else _NO_VALUES  # fmt: skip
    out, at = space(plan.size)
    if values.dtype == np.float64:
        _fill_compiled(out, at, plan, packed, values)
    else:
        _fill_numpy(plan, packed, values, out, at)
    return plan.size


def _pack(plan: _GroupPlan, group: SkeletonGroup) -> bytes:
    """The group's integer fields and confidences, packed in the plan's order."""
    ints: list = [*divmod(group.stamp_ns, _NS)]
    for s in group.skeletons:
        ints += (s.id, *divmod(s.src_time_ns, _NS), s.max_markers, s.max_links, s.confidence)
    try:
        return plan.packer.pack(*ints)
    except struct.error:
        msg = (
            "SkeletonGroup: a value is out of range of its message field: ids and seconds must "
            "fit int32, max_markers/max_links uint32"
        )
        raise CodecError(msg) from None


def _fill_compiled(
    out: np.ndarray, at: int, plan: _GroupPlan, packed: bytes, values: np.ndarray | SkeletonRows
) -> None:
    """``fill.fill_runs`` from concatenated values or from a group's ``SkeletonRows``."""
    from hiros_core.fill import fill_runs

    if isinstance(values, SkeletonRows):
        sources = (values.bounding_boxes, values.markers, values.links)
        boxes, markers, links = (np.ascontiguousarray(a).reshape(-1) for a in sources)
        fill_runs(out, at, plan.message, packed, plan.field_runs, boxes, markers, links,
                  plan.stack_runs)  # fmt: skip
    else:
        fill_runs(out, at, plan.message, packed, plan.field_runs, values, values, values,
                  plan.runs)  # fmt: skip


_STACK_PLANS: dict[tuple, tuple[Layout, _GroupPlan | None]] = {}  # (layout kept alive, plan)


def _stack_plan(group: SkeletonGroup, stack: SkeletonRows) -> _GroupPlan | None:
    """The plan of a group whose skeletons are ``stack``'s rows, keyed by the stack's masks.

    None when the stack's rows are not float64 (the general path converts them).
    """
    layout = group.skeletons[0].layout
    key = (
        group.frame_id,
        id(layout),
        tuple([s.src_frame for s in group.skeletons]),
        stack.marker_present.tobytes(),
        stack.link_present.tobytes(),
    )
    found = _STACK_PLANS.get(key)
    if found is not None and found[0] is layout:
        return found[1]
    if len(_STACK_PLANS) >= _GROUP_PLAN_CAPACITY:
        _STACK_PLANS.clear()
    usable = all(s.layout is layout for s in group.skeletons) and all(
        a.dtype == np.float64 for a in (stack.markers, stack.links, stack.bounding_boxes)
    )
    plan = _plan_of(group) if usable else None
    _STACK_PLANS[key] = (layout, plan)
    return plan


_NO_VALUES = np.empty(0)


def _fill_numpy(
    plan: _GroupPlan, packed: bytes, values: np.ndarray, out: np.ndarray, at: int
) -> None:
    """The numpy form of ``fill.fill_runs`` (the reference it is tested against)."""
    scratch = plan.template.copy()
    scratch[plan.field_index] = np.frombuffer(packed, dtype=np.uint8)
    if values.size:
        scratch[_LEAD + HEADER_SIZE :].view("<f8")[plan.floats] = values
    out[at : at + plan.size] = scratch[_LEAD : _LEAD + plan.size]


def _plan_of(group: SkeletonGroup) -> _GroupPlan:
    """The group's cached plan, built on first use (keyed by frames, layouts, presence)."""
    skeletons = group.skeletons
    keys = [
        (s.src_frame, id(s.layout), s.marker_present.tobytes(), s.link_present.tobytes())
        for s in skeletons
    ]
    group_key = (group.frame_id, *keys)
    plan = _GROUP_PLANS.get(group_key)
    if plan is None:
        if len(_GROUP_PLANS) >= _GROUP_PLAN_CAPACITY:
            _GROUP_PLANS.clear()
        header = _group_header(group)
        offset = header.size - HEADER_SIZE
        phased = []
        for skeleton, (frame, _, markers, links) in zip(skeletons, keys, strict=True):
            key = (frame, skeleton.layout, markers, links)
            phased.append((*key, offset % 8))
            offset += _skeleton_block_size(skeleton, key, offset % 8)
        plan = _GROUP_PLANS[group_key] = _build_group_plan(group, phased)
    return plan


def _skeleton_block_size(skeleton: Skeleton, key: tuple, phase: int) -> int:
    """Bytes of one skeleton's block at alignment ``phase`` (its plan, built if new)."""
    key = (*key, phase)
    plan = _SKELETON_PLANS.get(key) or _SKELETON_PLANS.put(
        key, _build_skeleton_plan(skeleton, phase), phase
    )
    return plan.size


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
    readings = _GROUP_READINGS.get(size)
    if readings:
        raw = np.frombuffer(data, dtype=np.uint8)
        buffer = np.empty(readings[0].words.size * 8, dtype=np.uint8)
        buffer[_LEAD : _LEAD + size] = raw
        words = buffer.view("<u8")
        for reading in readings:
            differ = np.bitwise_xor(words, reading.words)
            differ &= reading.mask
            if not differ.any():
                return _group_from_reading(reading, buffer)
    group = _decode_group_by_skeleton(data)
    reading = _group_reading(group, size)
    if reading is not None:
        found = _GROUP_READINGS.setdefault(size, [])
        found.insert(0, reading)
        del found[_GROUP_READING_CANDIDATES:]
        if len(_GROUP_READINGS) > _GROUP_PLAN_CAPACITY:
            _GROUP_READINGS.clear()
    return group


def _group_from_reading(reading: _GroupReading, buffer: np.ndarray) -> SkeletonGroup:
    plan = reading.plan
    floats = buffer[_LEAD + HEADER_SIZE :].view("<f8")
    floats[reading.scratch : reading.scratch + STATE_WIDTH] = np.nan
    if reading.stack is not None:
        return _stacked_group(reading, buffer, floats)
    values = floats[plan.floats]
    sec, nanosec = _STAMP_STRUCT.unpack_from(buffer, plan.stamp_at)
    skeletons = []
    for (head_at, maxes_at, box_at), (layout, frame, present, link_present, start) in zip(
        plan.fields, reading.skeletons, strict=True
    ):
        skeleton_id, src_sec, src_nanosec = _HEAD_STRUCT.unpack_from(buffer, head_at)
        max_markers, max_links = _MAXES_STRUCT.unpack_from(buffer, maxes_at)
        (confidence,) = _CONFIDENCE_STRUCT.unpack_from(buffer, box_at)
        markers_at = start + BOX_WIDTH
        links_at = markers_at + layout.n_joints * STATE_WIDTH
        skeletons.append(
            Skeleton(
                skeleton_id, src_sec * _NS + src_nanosec, frame, layout,
                values[markers_at:links_at].reshape(-1, STATE_WIDTH),
                values[links_at : links_at + layout.n_links * STATE_WIDTH].reshape(
                    -1, STATE_WIDTH
                ),
                present.copy(), link_present.copy(), confidence,
                values[start:markers_at], max_markers, max_links,
            )
        )  # fmt: skip
    return SkeletonGroup(sec * _NS + nanosec, reading.frame_id, skeletons)


def _stacked_group(reading: _GroupReading, buffer: np.ndarray, floats: np.ndarray) -> SkeletonGroup:
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
        [sec * _NS + nanosec for sec, nanosec in zip(values[3::6], values[4::6], strict=True)],
        stack.frames,
        stack.layout,
        values[7::6],
        max_sizes=list(zip(values[5::6], values[6::6], strict=True)),
    )
    return SkeletonGroup(values[0] * _NS + values[1], reading.frame_id, skeletons)


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
        plan = _SKELETON_PLANS.find_at(raw, reader.pos, phase)
        if plan is None:
            skeleton = _parse_skeleton(reader)
            _SKELETON_PLANS.put(
                _skeleton_key(skeleton, phase), _build_skeleton_plan(skeleton, phase), phase
            )
        else:
            skeleton = _skeleton_from_block(plan, raw, reader.pos)
            reader.pos += plan.size
        skeletons.append(skeleton)
    reader.done()
    return SkeletonGroup(stamp_sec * _NS + stamp_nanosec, frame_id, skeletons)


def _skeleton_from_block(plan: Plan, raw: np.ndarray, start: int) -> Skeleton:
    shape: _SkeletonShape = plan.meta  # type: ignore[assignment]
    values = plan.gather_all(raw, start)
    head = values["head"].view(_HEAD).ravel()
    maxes = values["maxes"].view(_MAXES).ravel()
    box = values["box"].view("<f8").ravel()
    skeleton = Skeleton.empty(shape.layout, skeleton_id=int(head["id"][0]))
    skeleton.src_time_ns = int(_join_ns(head)[0])
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
    src_time_ns = reader.i32() * _NS + reader.u32()
    src_frame = reader.string()
    max_markers, max_links = reader.u32(), reader.u32()
    box = reader.floats(_BOX_FLOATS)
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


# --------------------------------------------------------------------------- MarkerArray


@dataclass(frozen=True)
class MarkerAttachments:
    """The rarely used media fields of a Marker, kept so that decoding loses nothing."""

    texture_resource: str = ""
    texture_stamp_ns: int = 0
    texture_frame_id: str = ""
    texture_format: str = ""
    texture_data: bytes = b""
    uv_coordinates: tuple[tuple[float, float], ...] = ()
    mesh_resource: str = ""
    mesh_filename: str = ""
    mesh_data: bytes = b""


_NO_ATTACHMENTS = MarkerAttachments()


@dataclass(eq=False)
class MarkerArrayData:
    """A ``visualization_msgs/MarkerArray`` of N markers as columns.

    Attributes:
        stamps_ns: ``(N,)`` header stamps in ns.
        frame_ids, namespaces, texts: N strings each.
        ids, types, actions: ``(N,)`` int32 (types/actions as in visualization_msgs/Marker).
        poses: ``(N, 7)`` position x, y, z and orientation x, y, z, w.
        scales: ``(N, 3)``; colors: ``(N, 4)`` float32 r, g, b, a.
        lifetimes_ns: ``(N,)``; frame_locked, mesh_use_embedded_materials: ``(N,)`` bool.
        points: N arrays ``(k, 3)``; point_colors: N arrays ``(k, 4)`` float32.
        attachments: N ``MarkerAttachments`` (textures, uv, meshes).

    """

    stamps_ns: np.ndarray
    frame_ids: list[str]
    namespaces: list[str]
    ids: np.ndarray
    types: np.ndarray
    actions: np.ndarray
    poses: np.ndarray
    scales: np.ndarray
    colors: np.ndarray
    lifetimes_ns: np.ndarray
    frame_locked: np.ndarray
    points: list[np.ndarray]
    point_colors: list[np.ndarray]
    texts: list[str]
    attachments: list[MarkerAttachments] = field(default_factory=list)
    mesh_use_embedded_materials: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def __post_init__(self) -> None:
        n = len(self.ids)
        if not self.attachments:
            self.attachments = [_NO_ATTACHMENTS] * n
        if self.mesh_use_embedded_materials.size != n:
            self.mesh_use_embedded_materials = np.zeros(n, dtype=bool)

    def __len__(self) -> int:
        return len(self.ids)

    @classmethod
    def new(cls, n: int, *, frame_id: str = "", stamp_ns: int = 0) -> MarkerArrayData:
        """N SPHERE markers with action ADD, identity orientation, 5 cm, opaque white."""
        poses = np.zeros((n, 7))
        poses[:, 6] = 1.0
        return cls(
            stamps_ns=np.full(n, stamp_ns, dtype=np.int64),
            frame_ids=[frame_id] * n,
            namespaces=[""] * n,
            ids=np.arange(n, dtype=np.int32),
            types=np.full(n, 2, dtype=np.int32),
            actions=np.zeros(n, dtype=np.int32),
            poses=poses,
            scales=np.full((n, 3), 0.05),
            colors=np.ones((n, 4), dtype=np.float32),
            lifetimes_ns=np.zeros(n, dtype=np.int64),
            frame_locked=np.zeros(n, dtype=bool),
            points=[np.empty((0, 3))] * n,
            point_colors=[np.empty((0, 4), dtype=np.float32)] * n,
            texts=[""] * n,
        )


_MARKER_PLANS = PlanCache()


def _text_bytes(texts: list[str]) -> list[bytes]:
    """Each text as CDR content (UTF-8, ended at a NUL as rclpy does)."""
    if not any(texts):
        return [b""] * len(texts)
    try:
        return [text.encode("utf-8").split(b"\x00", 1)[0] for text in texts]
    except UnicodeEncodeError as exc:
        msg = f"cannot encode marker text: {exc.reason}"
        raise CodecError(msg) from None


def _marker_key(data: MarkerArrayData, texts: list[bytes]) -> tuple:
    # Texts change every frame (drivers put confidence levels there): only their lengths fix
    # the shape; their bytes are slots ``text<length>``.
    return (
        tuple(data.frame_ids),
        tuple(data.namespaces),
        tuple(map(len, texts)),
        tuple(map(len, data.points)),
        tuple(map(len, data.point_colors)),
        # hashing N dataclasses costs more than the encoding; most messages have none
        None if all(a is _NO_ATTACHMENTS for a in data.attachments) else tuple(data.attachments),
    )


@dataclass(frozen=True)
class _MarkerShape:
    frame_ids: tuple[str, ...]
    namespaces: tuple[str, ...]
    text_slots: dict[str, np.ndarray]  # slot kind -> indices of the markers whose text it holds
    point_counts: np.ndarray
    color_counts: np.ndarray
    attachments: tuple[MarkerAttachments, ...]


def _build_marker_plan(data: MarkerArrayData, texts: list[bytes]) -> Plan:
    builder = PlanBuilder()
    builder.u32(len(data))
    for i in range(len(data)):
        builder.slot("stamp", 8, 4)
        builder.string(data.frame_ids[i])
        builder.string(data.namespaces[i])
        builder.slot("ita", 12, 4)
        builder.slot("pose_scale", 80, 8)
        builder.slot("color", 16, 4)
        builder.slot("lifetime", 8, 4)
        builder.slot("locked", 1, 1)
        builder.u32(len(data.points[i]))
        for _ in range(len(data.points[i])):
            builder.slot("points", 24, 8)
        builder.u32(len(data.point_colors[i]))
        for _ in range(len(data.point_colors[i])):
            builder.slot("point_colors", 16, 4)
        extra = data.attachments[i]
        builder.string(extra.texture_resource)
        sec, nanosec = divmod(extra.texture_stamp_ns, _NS)
        builder.i32(sec)
        builder.u32(nanosec)
        builder.string(extra.texture_frame_id)
        builder.string(extra.texture_format)
        builder.blob(extra.texture_data)
        builder.u32(len(extra.uv_coordinates))
        builder.align(4)
        builder.buf += np.asarray(extra.uv_coordinates, dtype="<f4").tobytes()
        builder.u32(len(texts[i]) + 1)
        if texts[i]:
            builder.slot(f"text{len(texts[i])}", len(texts[i]), 1)
        builder.u8(0)
        builder.string(extra.mesh_resource)
        builder.string(extra.mesh_filename)
        builder.blob(extra.mesh_data)
        builder.slot("embedded", 1, 1)
    return builder.build(
        _MarkerShape(
            tuple(map(_c_string, data.frame_ids)),
            tuple(map(_c_string, data.namespaces)),
            _text_slots(texts),
            np.array([len(p) for p in data.points], dtype=np.intp),
            np.array([len(c) for c in data.point_colors], dtype=np.intp),
            tuple(data.attachments),
        )
    )


def _text_slots(texts: list[bytes]) -> dict[str, np.ndarray]:
    lengths = np.array([len(t) for t in texts], dtype=np.intp)
    return {f"text{n}": np.flatnonzero(lengths == n) for n in np.unique(lengths[lengths > 0])}


def marker_array_plan(data: MarkerArrayData) -> Plan:
    """The (cached) plan ``encode_marker_array`` fills for messages shaped like ``data``.

    Its ``slots`` give the byte offset of every marker's fields (``stamp``, ``pose_scale``,
    ``points``, ...), for encoders that fill an encoded message's bytes themselves.
    """
    texts = _text_bytes(data.texts)
    key = _marker_key(data, texts)
    return _MARKER_PLANS.get(key) or _MARKER_PLANS.put(key, _build_marker_plan(data, texts))


def encode_marker_array(data: MarkerArrayData) -> bytes:
    """CDR bytes of ``visualization_msgs/msg/MarkerArray`` for the columns ``data``."""
    texts = _text_bytes(data.texts)
    key = _marker_key(data, texts)
    plan = _MARKER_PLANS.get(key) or _MARKER_PLANS.put(key, _build_marker_plan(data, texts))
    shape: _MarkerShape = plan.meta  # type: ignore[assignment]
    text_values = {
        kind: np.frombuffer(b"".join(texts[i] for i in indices), dtype=np.uint8)
        for kind, indices in shape.text_slots.items()
    }
    what = "MarkerArray"
    ita = np.empty(len(data), dtype=_ITA)
    ita["id"] = _checked(list(map(int, data.ids)), "<i4", f"{what} marker id")
    ita["type"], ita["action"] = data.types, data.actions
    pose_scale = np.concatenate(
        [np.asarray(data.poses, dtype="<f8"), np.asarray(data.scales, dtype="<f8")], axis=1
    )
    return plan.encode(
        {
            "stamp": _split_ns(data.stamps_ns, what),
            "ita": ita,
            "pose_scale": pose_scale,
            "color": np.asarray(data.colors, dtype="<f4"),
            "lifetime": _split_ns(data.lifetimes_ns, what),
            "locked": np.asarray(data.frame_locked, dtype=np.uint8),
            "points": _rows([np.asarray(p, dtype="<f8") for p in data.points], 3),
            "point_colors": _rows([np.asarray(c, dtype="<f4") for c in data.point_colors], 4),
            "embedded": np.asarray(data.mesh_use_embedded_materials, dtype=np.uint8),
            **text_values,
        }
    )


def decode_marker_array(data: bytes | bytearray | memoryview) -> MarkerArrayData:
    """Columns of a ``visualization_msgs/MarkerArray`` from CDR bytes; CodecError on bad bytes."""
    check_marker_array(data)  # past hiros_core.limits: refused before anything is made
    size = len(memoryview(data).cast("B"))
    buffer = aligned_copy(data)
    plan = _MARKER_PLANS.find_aligned(buffer, size)
    if plan is None:
        markers = _walk_marker_array(data)
        texts = _text_bytes(markers.texts)
        _MARKER_PLANS.put(_marker_key(markers, texts), _build_marker_plan(markers, texts))
        return markers
    shape: _MarkerShape = plan.meta  # type: ignore[assignment]
    ita = plan.gather_aligned(buffer, "ita", _ITA).ravel()
    pose_scale = plan.gather_aligned(buffer, "pose_scale", "<f8").reshape(-1, 10)
    points = plan.gather_aligned(buffer, "points", "<f8").reshape(-1, 3)
    point_colors = plan.gather_aligned(buffer, "point_colors", "<f4").reshape(-1, 4)
    return MarkerArrayData(
        stamps_ns=_join_ns(plan.gather_aligned(buffer, "stamp", _TIME).ravel()),
        frame_ids=list(shape.frame_ids),
        namespaces=list(shape.namespaces),
        ids=ita["id"].copy(),
        types=ita["type"].copy(),
        actions=ita["action"].copy(),
        poses=pose_scale[:, :7].copy(),
        scales=pose_scale[:, 7:].copy(),
        colors=plan.gather_aligned(buffer, "color", "<f4").reshape(-1, 4),
        lifetimes_ns=_join_ns(plan.gather_aligned(buffer, "lifetime", _TIME).ravel()),
        frame_locked=plan.gather_aligned(buffer, "locked", np.uint8).ravel().astype(bool),
        points=_split_rows(points, shape.point_counts),
        point_colors=_split_rows(point_colors, shape.color_counts),
        texts=_gather_texts(plan, buffer, shape),
        attachments=list(shape.attachments),
        mesh_use_embedded_materials=(
            plan.gather_aligned(buffer, "embedded", np.uint8).ravel().astype(bool)
        ),
    )


class MarkerFields(NamedTuple):
    """The columns of a MarkerArray that say where joints are (what a driver bridge reads).

    Same names, types and values as the ``MarkerArrayData`` columns of the same message.
    """

    stamps_ns: np.ndarray
    frame_ids: list[str]
    namespaces: list[str]
    ids: np.ndarray
    actions: np.ndarray
    poses: np.ndarray
    texts: list[str]


def decode_marker_fields(data: bytes | bytearray | memoryview) -> MarkerFields:
    """``decode_marker_array`` restricted to ``MarkerFields``; CodecError on bad bytes.

    Skips colours, scales, points, lifetimes and media: about half the decoding of a driver
    message.
    """
    check_marker_array(data)  # past hiros_core.limits: refused before anything is made
    size = len(memoryview(data).cast("B"))
    buffer = aligned_copy(data)
    plan = _MARKER_PLANS.find_aligned(buffer, size)
    if plan is None:
        full = decode_marker_array(data)
        return MarkerFields(
            full.stamps_ns, full.frame_ids, full.namespaces, full.ids, full.actions, full.poses,
            full.texts,
        )  # fmt: skip
    shape: _MarkerShape = plan.meta  # type: ignore[assignment]
    ita = plan.gather_aligned(buffer, "ita", _ITA).ravel()
    return MarkerFields(
        stamps_ns=_join_ns(plan.gather_aligned(buffer, "stamp", _TIME).ravel()),
        frame_ids=list(shape.frame_ids),
        namespaces=list(shape.namespaces),
        ids=ita["id"].copy(),
        actions=ita["action"].copy(),
        poses=plan.gather_aligned(buffer, "pose_scale", "<f8").reshape(-1, 10)[:, :7].copy(),
        texts=_gather_texts(plan, buffer, shape),
    )


def _split_rows(rows: np.ndarray, counts: np.ndarray) -> list[np.ndarray]:
    """Per-marker arrays; markers without points (most drivers) share one empty array."""
    if not rows.size:
        empty = rows[:0]
        empty.flags.writeable = False
        return [empty] * len(counts)
    return np.split(rows, np.cumsum(counts)[:-1])


def _gather_texts(plan: Plan, buffer: np.ndarray, shape: _MarkerShape) -> list[str]:
    texts = [""] * len(shape.frame_ids)
    for kind, indices in shape.text_slots.items():
        rows = plan.gather_aligned(buffer, kind, np.uint8)
        width = rows.shape[1]
        if rows.all() and rows.max() < 0x80:
            # ASCII without NULs (confidence digits, labels): one decode, cut every ``width``
            joined = rows.tobytes().decode("ascii")
            decoded = list(joined) if width == 1 else [
                joined[i : i + width] for i in range(0, len(joined), width)
            ]  # fmt: skip
        else:
            try:  # fixed-width byte strings, decoded together
                decoded = np.char.decode(rows.view(f"S{width}").ravel(), "utf-8").tolist()
            except UnicodeDecodeError:
                msg = "cannot decode MarkerArray: a marker text is not UTF-8"
                raise CodecError(msg) from None
        for index, text in zip(indices.tolist(), decoded, strict=True):
            texts[index] = text
    return texts


class _IrregularError(Exception):
    """The fast walk met something it leaves to ``_parse_marker_array`` (which names it)."""


_I32_U32 = struct.Struct("<iI")
_U32 = struct.Struct("<I")
_ITA_STRUCT = struct.Struct("<iii")
_POSE_SCALE_STRUCT = struct.Struct("<10d")
_COLOR_STRUCT = struct.Struct("<4f")
# "" resource, (0, 0) stamp, "" frame, "" format, no data, no uv (x: padding, not compared)
_MEDIA_STRUCT = struct.Struct("<IB3xiIIB3xIB3xII")
_NO_MEDIA = (1, 0, 0, 0, 1, 0, 1, 0, 0, 0)
# "" mesh resource, "" mesh file, no mesh data, then mesh_use_embedded_materials
_MESH_STRUCT = struct.Struct("<IB3xIB3xIB")
_NO_MESH = (1, 0, 1, 0, 0)


def _walk_marker_array(data: bytes | bytearray | memoryview) -> MarkerArrayData:
    """``_parse_marker_array`` for well-formed messages, a few times faster.

    A message of a new shape is walked once before its plan exists; with ~15 fields per
    marker, the reader's per-field calls cost ~10 ms per driver message. Here positions are
    plain integers and fixed runs are unpacked together; anything unusual (truncation, bad
    strings, media attachments) is left to ``_parse_marker_array``, so errors and odd
    messages read exactly as before.
    """
    raw = bytes(data)
    try:
        return _walk(raw)
    except (_IrregularError, struct.error, IndexError, UnicodeDecodeError):
        return _parse_marker_array(raw)


def _walk(raw: bytes) -> MarkerArrayData:  # noqa: PLR0915 - one flat loop on purpose
    size = len(raw)
    if size < HEADER_SIZE + 4 or raw[0] != 0 or raw[1] != 1:
        raise _IrregularError
    u32, i32_u32 = _U32.unpack_from, _I32_U32.unpack_from

    def string(pos: int) -> tuple[str, int]:
        pos += -pos % 4  # payload offset = pos - 4: same residue mod 4
        (n,) = u32(raw, pos)
        end = pos + 4 + n
        if n == 0 or end > size or raw[end - 1] != 0:
            raise _IrregularError
        return raw[pos + 4 : end - 1].split(b"\x00", 1)[0].decode("utf-8"), end

    (n,) = u32(raw, 4)
    if n * 150 > size - 8:
        raise _IrregularError
    pos = 8
    stamps, lifetimes, frames, namespaces, itas, pose_scales, colors, locked = (
        [], [], [], [], [], [], [], []
    )  # fmt: skip
    points, point_colors, texts, embedded = [], [], [], []
    for _ in range(n):
        pos += -pos % 4
        sec, nanosec = i32_u32(raw, pos)
        stamps.append(sec * _NS + nanosec)
        frame, pos = string(pos + 8)
        namespace, pos = string(pos)
        frames.append(frame)
        namespaces.append(namespace)
        pos += -pos % 4
        itas.append(_ITA_STRUCT.unpack_from(raw, pos))
        pos += 12
        pos += (4 - pos) % 8  # 8-aligned in the payload
        pose_scales.append(_POSE_SCALE_STRUCT.unpack_from(raw, pos))
        pos += 80  # 8-aligned, so the colour needs no padding
        colors.append(_COLOR_STRUCT.unpack_from(raw, pos))
        sec, nanosec = i32_u32(raw, pos + 16)
        lifetimes.append(sec * _NS + nanosec)
        locked.append(raw[pos + 24])
        pos += 25
        pos += -pos % 4
        (count,) = u32(raw, pos)
        pos += 4
        pos += (4 - pos) % 8
        if count * 24 > size - pos:
            raise _IrregularError
        points.append(np.frombuffer(raw, "<f8", 3 * count, pos).reshape(-1, 3))
        pos += 24 * count
        pos += -pos % 4
        (count,) = u32(raw, pos)
        pos += 4
        if count * 16 > size - pos:
            raise _IrregularError
        point_colors.append(np.frombuffer(raw, "<f4", 4 * count, pos).reshape(-1, 4))
        pos += 16 * count
        # texture resource, stamp, frame, format, data and uv coordinates, all empty (else
        # the reader's way, which keeps them as attachments); padding bytes are not compared
        pos += -pos % 4
        if _MEDIA_STRUCT.unpack_from(raw, pos) != _NO_MEDIA:
            raise _IrregularError
        text, pos = string(pos + _MEDIA_STRUCT.size)
        texts.append(text)
        pos += -pos % 4
        *mesh, flag = _MESH_STRUCT.unpack_from(raw, pos)
        if tuple(mesh) != _NO_MESH:
            raise _IrregularError
        embedded.append(flag)
        pos += _MESH_STRUCT.size
    if size - pos > 3:
        raise _IrregularError
    if any(b > 1 for b in locked) or any(b > 1 for b in embedded):
        raise _IrregularError  # let the reader decide what such bytes mean
    ita = np.array(itas, dtype=np.int32).reshape(-1, 3)
    pose_scale = np.array(pose_scales, dtype=np.float64).reshape(-1, 10)
    return MarkerArrayData(
        stamps_ns=np.array(stamps, dtype=np.int64),
        frame_ids=frames,
        namespaces=namespaces,
        ids=ita[:, 0].copy(),
        types=ita[:, 1].copy(),
        actions=ita[:, 2].copy(),
        poses=pose_scale[:, :7].copy(),
        scales=pose_scale[:, 7:].copy(),
        colors=np.array(colors, dtype=np.float32).reshape(-1, 4),
        lifetimes_ns=np.array(lifetimes, dtype=np.int64),
        frame_locked=np.array(locked, dtype=bool),
        points=[p.copy() for p in points],
        point_colors=[c.copy() for c in point_colors],
        texts=texts,
        attachments=[_NO_ATTACHMENTS] * n,
        mesh_use_embedded_materials=np.array(embedded, dtype=bool),
    )


def _parse_marker_array(data: bytes | bytearray | memoryview) -> MarkerArrayData:
    reader = CdrReader(data, "visualization_msgs/MarkerArray")
    n = reader.count(150)
    out = MarkerArrayData.new(n)
    out.attachments = []
    out.points, out.point_colors = [], []
    for i in range(n):
        out.stamps_ns[i] = reader.i32() * _NS + reader.u32()
        out.frame_ids[i] = reader.string()
        out.namespaces[i] = reader.string()
        out.ids[i], out.types[i], out.actions[i] = reader.i32(), reader.i32(), reader.i32()
        pose_scale = reader.floats(10)
        out.poses[i], out.scales[i] = pose_scale[:7], pose_scale[7:]
        out.colors[i] = reader.floats(4, "<f4")
        out.lifetimes_ns[i] = reader.i32() * _NS + reader.u32()
        out.frame_locked[i] = bool(reader.u8())
        out.points.append(reader.floats(3 * reader.count(24)).reshape(-1, 3))
        out.point_colors.append(reader.floats(4 * reader.count(16), "<f4").reshape(-1, 4))
        texture_resource = reader.string()
        texture_stamp = reader.i32() * _NS + reader.u32()
        texture_frame, texture_format = reader.string(), reader.string()
        texture_data = reader.blob()
        uv = reader.floats(2 * reader.count(8), "<f4").reshape(-1, 2)
        out.texts[i] = reader.string()
        mesh_resource, mesh_filename = reader.string(), reader.string()
        mesh_data = reader.blob()
        out.mesh_use_embedded_materials[i] = bool(reader.u8())
        out.attachments.append(
            MarkerAttachments(
                texture_resource,
                texture_stamp,
                texture_frame,
                texture_format,
                texture_data,
                tuple(map(tuple, uv.tolist())),
                mesh_resource,
                mesh_filename,
                mesh_data,
            )
        )
    reader.done()
    return out
