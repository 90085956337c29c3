"""The MarkerArray codec: ``visualization_msgs/MarkerArray`` bytes <-> ``MarkerArrayData`` columns.

Encoding fills a plan per message shape (frames, namespaces, text lengths, point counts); a
message of a known shape is decoded by one gather per kind of field, and a new one walked once
(``marker_walk``; ``_parse_marker_array``'s field reader for anything unusual), which teaches
its plan. ``decode_marker_fields`` reads only the columns a driver bridge needs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from hiros_core.cdr import CdrReader, Plan, PlanBuilder, PlanCache, aligned_copy
from hiros_core.codec.fields import (
    NS,
    TIME_DTYPE,
    c_string,
    checked_ints,
    join_ns,
    split_ns,
    stacked_rows,
)
from hiros_core.errors import CodecError
from hiros_core.limits import check_marker_array

_ITA = np.dtype([("id", "<i4"), ("type", "<i4"), ("action", "<i4")])


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


MARKER_PLANS = PlanCache()


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
        sec, nanosec = divmod(extra.texture_stamp_ns, NS)
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
            tuple(map(c_string, data.frame_ids)),
            tuple(map(c_string, data.namespaces)),
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
    return MARKER_PLANS.get(key) or MARKER_PLANS.put(key, _build_marker_plan(data, texts))


def encode_marker_array(data: MarkerArrayData) -> bytes:
    """CDR bytes of ``visualization_msgs/msg/MarkerArray`` for the columns ``data``."""
    texts = _text_bytes(data.texts)
    key = _marker_key(data, texts)
    plan = MARKER_PLANS.get(key) or MARKER_PLANS.put(key, _build_marker_plan(data, texts))
    shape: _MarkerShape = plan.meta  # type: ignore[assignment]
    text_values = {
        kind: np.frombuffer(b"".join(texts[i] for i in indices), dtype=np.uint8)
        for kind, indices in shape.text_slots.items()
    }
    what = "MarkerArray"
    ita = np.empty(len(data), dtype=_ITA)
    ita["id"] = checked_ints(list(map(int, data.ids)), "<i4", f"{what} marker id")
    ita["type"], ita["action"] = data.types, data.actions
    pose_scale = np.concatenate(
        [np.asarray(data.poses, dtype="<f8"), np.asarray(data.scales, dtype="<f8")], axis=1
    )
    return plan.encode(
        {
            "stamp": split_ns(data.stamps_ns, what),
            "ita": ita,
            "pose_scale": pose_scale,
            "color": np.asarray(data.colors, dtype="<f4"),
            "lifetime": split_ns(data.lifetimes_ns, what),
            "locked": np.asarray(data.frame_locked, dtype=np.uint8),
            "points": stacked_rows([np.asarray(p, dtype="<f8") for p in data.points], 3),
            "point_colors": stacked_rows(
                [np.asarray(c, dtype="<f4") for c in data.point_colors], 4
            ),
            "embedded": np.asarray(data.mesh_use_embedded_materials, dtype=np.uint8),
            **text_values,
        }
    )


def _known_shape(data: bytes | bytearray | memoryview) -> tuple[np.ndarray, Plan] | MarkerArrayData:
    """The message's aligned bytes and the plan of its shape; a new shape's columns, walked.

    A new shape is walked once (``_walk_marker_array``) and its plan learnt, so the next
    message of that shape is gathered. Raises CodecError on bad bytes.
    """
    check_marker_array(data)  # past hiros_core.limits: refused before anything is made
    size = len(memoryview(data).cast("B"))
    buffer = aligned_copy(data)
    plan = MARKER_PLANS.find_aligned(buffer, size)
    if plan is not None:
        return buffer, plan
    markers = _walk_marker_array(data)
    texts = _text_bytes(markers.texts)
    MARKER_PLANS.put(_marker_key(markers, texts), _build_marker_plan(markers, texts))
    return markers


def decode_marker_array(data: bytes | bytearray | memoryview) -> MarkerArrayData:
    """Columns of a ``visualization_msgs/MarkerArray`` from CDR bytes; CodecError on bad bytes."""
    found = _known_shape(data)
    if isinstance(found, MarkerArrayData):
        return found
    buffer, plan = found
    shape: _MarkerShape = plan.meta  # type: ignore[assignment]
    ita = plan.gather_aligned(buffer, "ita", _ITA).ravel()
    pose_scale = plan.gather_aligned(buffer, "pose_scale", "<f8").reshape(-1, 10)
    points = plan.gather_aligned(buffer, "points", "<f8").reshape(-1, 3)
    point_colors = plan.gather_aligned(buffer, "point_colors", "<f4").reshape(-1, 4)
    return MarkerArrayData(
        stamps_ns=join_ns(plan.gather_aligned(buffer, "stamp", TIME_DTYPE).ravel()),
        frame_ids=list(shape.frame_ids),
        namespaces=list(shape.namespaces),
        ids=ita["id"].copy(),
        types=ita["type"].copy(),
        actions=ita["action"].copy(),
        poses=pose_scale[:, :7].copy(),
        scales=pose_scale[:, 7:].copy(),
        colors=plan.gather_aligned(buffer, "color", "<f4").reshape(-1, 4),
        lifetimes_ns=join_ns(plan.gather_aligned(buffer, "lifetime", TIME_DTYPE).ravel()),
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
    found = _known_shape(data)
    if isinstance(found, MarkerArrayData):
        return MarkerFields(
            found.stamps_ns, found.frame_ids, found.namespaces, found.ids, found.actions,
            found.poses, found.texts,
        )  # fmt: skip
    buffer, plan = found
    shape: _MarkerShape = plan.meta  # type: ignore[assignment]
    ita = plan.gather_aligned(buffer, "ita", _ITA).ravel()
    return MarkerFields(
        stamps_ns=join_ns(plan.gather_aligned(buffer, "stamp", TIME_DTYPE).ravel()),
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


def _walk_marker_array(data: bytes | bytearray | memoryview) -> MarkerArrayData:
    """``_parse_marker_array`` for regular messages (``marker_walk``), a few times faster.

    A message of a new shape is walked once before its plan exists; with ~15 fields per
    marker, the reader's per-field calls cost ~10 ms per driver message. The compiled walk
    finds every field (the same walk reads a recording's driver messages); anything it does
    not take (truncation, media attachments, booleans past 1) and text that is not UTF-8 are
    left to ``_parse_marker_array``, so errors and odd messages read exactly as before.
    """
    from hiros_core.codec import marker_walk

    raw = bytes(data)
    buf = np.frombuffer(raw, dtype=np.uint8)
    ends = np.array([len(raw)], dtype=np.int64)
    _, regular, table = marker_walk.walk_markers(buf, np.zeros(1, dtype=np.int64), ends)
    if not regular[0]:
        return _parse_marker_array(raw)
    try:
        return _walked(raw, buf, table)
    except UnicodeDecodeError:
        return _parse_marker_array(raw)


def _walked(raw: bytes, buf: np.ndarray, table: np.ndarray) -> MarkerArrayData:
    """The columns of a regular message from its ``marker_walk`` table."""
    from hiros_core.codec.marker_walk import (
        EMBEDDED,
        FRAME,
        ID,
        LIFETIME,
        LOCKED,
        NAMESPACE,
        POINT_COLORS,
        POINTS,
        POSE,
        STAMP,
        TEXT,
    )

    def texts(column: int) -> list[str]:
        spans = table[:, column : column + 2].tolist()
        return [raw[a:b].split(b"\x00", 1)[0].decode("utf-8") for a, b in spans]

    pose_scale = _gathered(buf, table[:, POSE], 10, np.float64)
    return MarkerArrayData(
        stamps_ns=table[:, STAMP].copy(),
        frame_ids=texts(FRAME),
        namespaces=texts(NAMESPACE),
        ids=table[:, ID].astype(np.int32),
        types=table[:, ID + 1].astype(np.int32),
        actions=table[:, ID + 2].astype(np.int32),
        poses=pose_scale[:, :7].copy(),
        scales=pose_scale[:, 7:].copy(),
        colors=_gathered(buf, table[:, POSE] + 80, 4, np.float32),
        lifetimes_ns=table[:, LIFETIME].copy(),
        frame_locked=table[:, LOCKED].astype(bool),
        points=[
            np.frombuffer(raw, "<f8", 3 * count, at).reshape(-1, 3).copy()
            for at, count in table[:, POINTS : POINTS + 2].tolist()
        ],
        point_colors=[
            np.frombuffer(raw, "<f4", 4 * count, at).reshape(-1, 4).copy()
            for at, count in table[:, POINT_COLORS : POINT_COLORS + 2].tolist()
        ],
        texts=texts(TEXT),
        attachments=[_NO_ATTACHMENTS] * len(table),
        mesh_use_embedded_materials=table[:, EMBEDDED].astype(bool),
    )


def _gathered(buf: np.ndarray, starts: np.ndarray, width: int, dtype: type) -> np.ndarray:
    """``(n, width)`` values of ``dtype`` stored from each of the byte offsets ``starts``."""
    size = width * np.dtype(dtype).itemsize
    return buf[starts[:, None] + np.arange(size)].view(dtype)


def _parse_marker_array(data: bytes | bytearray | memoryview) -> MarkerArrayData:
    reader = CdrReader(data, "visualization_msgs/MarkerArray")
    n = reader.count(150)
    out = MarkerArrayData.new(n)
    out.attachments = []
    out.points, out.point_colors = [], []
    for i in range(n):
        out.stamps_ns[i] = reader.i32() * NS + reader.u32()
        out.frame_ids[i] = reader.string()
        out.namespaces[i] = reader.string()
        out.ids[i], out.types[i], out.actions[i] = reader.i32(), reader.i32(), reader.i32()
        pose_scale = reader.floats(10)
        out.poses[i], out.scales[i] = pose_scale[:7], pose_scale[7:]
        out.colors[i] = reader.floats(4, "<f4")
        out.lifetimes_ns[i] = reader.i32() * NS + reader.u32()
        out.frame_locked[i] = bool(reader.u8())
        out.points.append(reader.floats(3 * reader.count(24)).reshape(-1, 3))
        out.point_colors.append(reader.floats(4 * reader.count(16), "<f4").reshape(-1, 4))
        texture_resource = reader.string()
        texture_stamp = reader.i32() * NS + reader.u32()
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
