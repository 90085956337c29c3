"""The SkeletonGroup codec's plans: where each field of a group's message goes, and their caches.

A skeleton's block plan (``cdr.BlockPlans``, keyed by frame, layout and present ids) is laid out
once; a group's plan joins its skeletons' blocks behind the header, and a reading adds what
decoding needs to recognise a known message by its constant bytes. ``group_encode`` and
``group_decode`` fill and read them.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from hiros_core.cdr import HEADER_SIZE, BlockPlans, Plan, PlanBuilder, PlanCache
from hiros_core.codec.fields import c_string
from hiros_core.layouts import Layout
from hiros_core.model import BOX_WIDTH, STATE_WIDTH, Skeleton, SkeletonGroup

HEAD_STRUCT = struct.Struct("<iiI")
STAMP_STRUCT = struct.Struct("<iI")
MAXES_STRUCT = struct.Struct("<II")
CONFIDENCE_STRUCT = struct.Struct("<d")
_ROW_BYTES = STATE_WIDTH * 8
_BOX, _MARKERS, _LINKS = 0, 1, 2  # sources of a plan's float runs (``fill.fill_runs``)
BOX_FLOATS = 1 + BOX_WIDTH  # skeleton confidence + bounding box


@dataclass(frozen=True)
class SkeletonShape:
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
SKELETON_PLANS = BlockPlans()
GROUP_HEADER = PlanCache(capacity=64)


def skeleton_key(skeleton: Skeleton, phase: int) -> tuple:
    """What fixes a skeleton's block plan: frame, layout, present ids, alignment ``phase``."""
    return (
        skeleton.src_frame,
        skeleton.layout,
        skeleton.marker_present.tobytes(),
        skeleton.link_present.tobytes(),
        phase,
    )


def build_skeleton_plan(skeleton: Skeleton, payload_offset: int) -> Plan:
    """The block plan of ``skeleton``'s shape, its block at ``payload_offset`` (mod 8)."""
    builder = PlanBuilder(payload_offset)
    layout = skeleton.layout
    marker_ids = np.flatnonzero(skeleton.marker_present)
    link_ids = np.flatnonzero(skeleton.link_present)
    builder.slot("head", 12, 4)
    builder.string(skeleton.src_frame)
    builder.slot("maxes", 8, 4)
    builder.slot("box", BOX_FLOATS * 8, 8)
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
        SkeletonShape(
            c_string(skeleton.src_frame),
            layout,
            marker_ids,
            link_ids,
            builder.slots["head"][0],
            builder.slots["maxes"][0],
            (
                floats("box", BOX_FLOATS),
                floats("markers", STATE_WIDTH),
                floats("links", STATE_WIDTH),
            ),
        )
    )


def _group_header(group: SkeletonGroup) -> Plan:
    key = (group.frame_id, len(group.skeletons))
    plan = GROUP_HEADER.get(key)
    if plan is None:
        builder = PlanBuilder()
        builder.slot("stamp", 8, 4)
        builder.string(group.frame_id)
        builder.u32(len(group.skeletons))
        plan = GROUP_HEADER.put(key, builder.build())
    return plan


@dataclass(frozen=True)
class GroupPlan:
    """A whole group's encoding: template, and where each skeleton's values go.

    ``floats`` indexes a float64 view of the payload for the concatenation, per skeleton, of
    its bounding box ``(22,)``, all ``J`` marker rows and all ``L`` link rows: rows the
    skeleton does not carry point into a scratch row past the message end, so encoding
    needs no per-skeleton selection of present rows. The template starts with ``LEAD``
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
        object.__setattr__(self, "message", self.template[LEAD : LEAD + self.size])


@dataclass(frozen=True)
class GroupReading:
    """What decoding needs beyond a ``GroupPlan``: how to recognise the message and read it.

    ``words``/``mask``: the template and its constant bytes as 8-byte words (``cdr.Plan``'s
    ``matches_aligned`` idea over the whole group); ``stacks``: the skeletons of each layout,
    read as the rows of one ``SkeletonRows``.
    """

    plan: GroupPlan
    frame_id: str
    words: np.ndarray
    mask: np.ndarray
    scratch: int  # float64 position of the scratch row (filled with NaN when decoding)
    stacks: tuple[StackReading, ...]  # one per layout, in order of first appearance


class StackReading(NamedTuple):
    """How the skeletons of one layout in a group are decoded as one ``SkeletonRows``.

    ``floats``: their float indices in the plan reordered field by field (every box, then
    every skeleton's marker rows, then every link rows), so one gather gives the three fields
    as contiguous blocks; ``people``: where they stand in the group; their presence masks and
    source frames.
    """

    layout: Layout
    floats: np.ndarray
    people: list[int]
    marker_present: np.ndarray  # (P, J)
    link_present: np.ndarray  # (P, L)
    frames: list[str]


GROUP_READINGS: dict[int, list[GroupReading]] = {}  # by message size, most recent first


def group_reading(group: SkeletonGroup, size: int) -> GroupReading | None:
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
        plan = SKELETON_PLANS.get((*key, phase)) or SKELETON_PLANS.put(
            (*key, phase), build_skeleton_plan(skeleton, phase), phase
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
    mask[np.concatenate(constant) + LEAD] = 0xFF
    words = np.zeros_like(mask)
    words[: plan.template.size] = plan.template
    return GroupReading(
        plan,
        group.frame_id,
        words.view("<u8"),
        mask.view("<u8"),
        (offset + (-offset) % 8) // 8,  # as _build_group_plan places it
        _stack_readings(group, plan),
    )


def _stack_readings(group: SkeletonGroup, plan: GroupPlan) -> tuple[StackReading, ...]:
    """The stack decoding of messages shaped like ``group``: one per layout."""
    skeletons = group.skeletons
    sizes = [BOX_WIDTH + (s.layout.n_joints + s.layout.n_links) * STATE_WIDTH for s in skeletons]
    starts = np.cumsum([0, *sizes])
    layouts = list({id(s.layout): s.layout for s in skeletons}.values())
    stacks = []
    for layout in layouts:
        people = [p for p, s in enumerate(skeletons) if s.layout is layout]
        per_person = np.array([plan.floats[starts[p] : starts[p + 1]] for p in people])
        marker_floats = layout.n_joints * STATE_WIDTH
        fields = np.split(per_person, [BOX_WIDTH, BOX_WIDTH + marker_floats], axis=1)
        stacks.append(
            StackReading(
                layout,
                np.concatenate([field.ravel() for field in fields]),
                people,
                np.array([skeletons[p].marker_present for p in people]),
                np.array([skeletons[p].link_present for p in people]),
                [skeletons[p].src_frame for p in people],
            )
        )
    return tuple(stacks)


GROUP_PLANS: dict[tuple, GroupPlan] = {}
GROUP_PLAN_CAPACITY = 256
LEAD = 8 - HEADER_SIZE  # template bytes before the CDR header: aligns the payload


def _build_group_plan(group: SkeletonGroup, keys: list[tuple]) -> GroupPlan:
    header = _group_header(group)
    offset = header.size - HEADER_SIZE
    templates = [np.zeros(LEAD, dtype=np.uint8), header.template]
    fields, indices, runs = [], [], []
    stamp_at = int(header.slots["stamp"][0]) + LEAD
    packed = [(stamp_at, STAMP_STRUCT)]
    blocks = []
    for skeleton, key in zip(group.skeletons, keys, strict=True):
        phase = offset % 8
        plan = SKELETON_PLANS.get(key) or SKELETON_PLANS.put(
            key, build_skeleton_plan(skeleton, phase), phase
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
        shape: SkeletonShape = plan.meta  # type: ignore[assignment]
        at = start + HEADER_SIZE + LEAD
        box_at = int(plan.slots["box"][0]) + at
        fields.append((at + shape.head_at, at + shape.maxes_at, box_at))
        packed += [(at + shape.head_at, HEAD_STRUCT), (at + shape.maxes_at, MAXES_STRUCT)]
        packed.append((box_at, CONFIDENCE_STRUCT))
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
    return GroupPlan(
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
        runs.append((template_at - LEAD, at, kind.size))
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


STACK_PLANS: dict[tuple, tuple[Layout, GroupPlan | None]] = {}  # (layout kept alive, plan)


def plan_of(group: SkeletonGroup) -> GroupPlan:
    """The group's cached plan, built on first use (keyed by frames, layouts, presence)."""
    skeletons = group.skeletons
    keys = [
        (s.src_frame, id(s.layout), s.marker_present.tobytes(), s.link_present.tobytes())
        for s in skeletons
    ]
    group_key = (group.frame_id, *keys)
    plan = GROUP_PLANS.get(group_key)
    if plan is None:
        if len(GROUP_PLANS) >= GROUP_PLAN_CAPACITY:
            GROUP_PLANS.clear()
        header = _group_header(group)
        offset = header.size - HEADER_SIZE
        phased = []
        for skeleton, (frame, _, markers, links) in zip(skeletons, keys, strict=True):
            key = (frame, skeleton.layout, markers, links)
            phased.append((*key, offset % 8))
            offset += _skeleton_block_size(skeleton, key, offset % 8)
        plan = GROUP_PLANS[group_key] = _build_group_plan(group, phased)
    return plan


def _skeleton_block_size(skeleton: Skeleton, key: tuple, phase: int) -> int:
    """Bytes of one skeleton's block at alignment ``phase`` (its plan, built if new)."""
    key = (*key, phase)
    plan = SKELETON_PLANS.get(key) or SKELETON_PLANS.put(
        key, build_skeleton_plan(skeleton, phase), phase
    )
    return plan.size
