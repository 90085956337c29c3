"""SkeletonGroup -> CDR bytes: a template copy plus the group's values, by the compiled filler.

The bytes are those of ``rclpy.serialization.serialize_message`` for the same message, padding
written as zeros. A group whose skeletons are the rows of one ``SkeletonRows`` stack is copied
from the stack itself (``fill.fill_runs``).
"""

from __future__ import annotations

import struct
from collections.abc import Callable

import numpy as np

from hiros_core.cdr import HEADER_SIZE
from hiros_core.codec.fields import NS
from hiros_core.codec.group_plans import (
    GROUP_PLAN_CAPACITY,
    LEAD,
    STACK_PLANS,
    GroupPlan,
    plan_of,
)
from hiros_core.errors import CodecError
from hiros_core.model import SkeletonGroup, SkeletonRows, shared_stack, warm_up_group


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
    plan = plan_of(group)
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


def _pack(plan: GroupPlan, group: SkeletonGroup) -> bytes:
    """The group's integer fields and confidences, packed in the plan's order."""
    ints: list = [*divmod(group.stamp_ns, NS)]
    for s in group.skeletons:
        ints += (s.id, *divmod(s.src_time_ns, NS), s.max_markers, s.max_links, s.confidence)
    try:
        return plan.packer.pack(*ints)
    except struct.error:
        msg = (
            "SkeletonGroup: a value is out of range of its message field: ids and seconds must "
            "fit int32, max_markers/max_links uint32"
        )
        raise CodecError(msg) from None


def _fill_compiled(
    out: np.ndarray, at: int, plan: GroupPlan, packed: bytes, values: np.ndarray | SkeletonRows
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


def _stack_plan(group: SkeletonGroup, stack: SkeletonRows) -> GroupPlan | None:
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
    found = STACK_PLANS.get(key)
    if found is not None and found[0] is layout:
        return found[1]
    if len(STACK_PLANS) >= GROUP_PLAN_CAPACITY:
        STACK_PLANS.clear()
    usable = all(s.layout is layout for s in group.skeletons) and all(
        a.dtype == np.float64 for a in (stack.markers, stack.links, stack.bounding_boxes)
    )
    plan = plan_of(group) if usable else None
    STACK_PLANS[key] = (layout, plan)
    return plan


_NO_VALUES = np.empty(0)


def _fill_numpy(
    plan: GroupPlan, packed: bytes, values: np.ndarray, out: np.ndarray, at: int
) -> None:
    """The numpy form of ``fill.fill_runs`` (the reference it is tested against)."""
    scratch = plan.template.copy()
    scratch[plan.field_index] = np.frombuffer(packed, dtype=np.uint8)
    if values.size:
        scratch[LEAD + HEADER_SIZE :].view("<f8")[plan.floats] = values
    out[at : at + plan.size] = scratch[LEAD : LEAD + plan.size]
