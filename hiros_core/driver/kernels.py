"""Compiled (numba) forms of the bridge's usual frame, same rows bit for bit as the numpy path.

The driver's usual message (every marker an ADD of a known joint, ids in increasing order, as
the ids of earlier messages showed) turns into marker rows by a dozen small numpy calls per
message in ``DriverBridge._kept_markers``/``_skeletons``; ``driver_rows`` does it in one call.
``driver_messages`` goes further for a recording: it reads the driver's MarkerArray CDR bytes
of many messages at once (a whole MCAP chunk) straight into marker rows, so that decoding costs
no Python work per marker and next to none per message.
Offsets named ``r`` are relative to a message's first byte; its CDR payload starts at 4, so
4-alignment is ``r``'s own and 8-alignment is ``r - 4``'s. The small helpers are inlined
(``inline="always"``): called per field of every marker, their calls cost a third of the walk.
Always the bridge's path for usual messages; imported at the bridge's first call, compiled on
first use and cached on disk (the rule: ``hiros_core.compiled``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["driver_messages", "driver_people", "driver_rows"]

_MIN_MARKER_BYTES = 150
"""The codec's lower bound on a Marker's CDR size: more markers than this allows is bad data."""
_MAX_LEVEL_DIGITS = 9


@njit(cache=True, inline="always")
def _finite_position(pose: np.ndarray, position_scale: float) -> bool:
    """Whether the scaled position is finite (as ``_fill_row`` requires)."""
    for k in range(3):
        value = pose[k]
        if position_scale != 1.0:
            value *= position_scale
        if not math.isfinite(value):
            return False
    return True


@njit(cache=True, inline="always")
def _fill_row(
    row: np.ndarray, pose: np.ndarray, level: float, position_scale: float, levels: float
) -> bool:
    """Write [confidence, position, orientation] of one joint into a NaN ``row``.

    ``pose`` is position and orientation (x, y, z, w); the orientation stays NaN when its
    squared norm is not positive (zero or NaN: the driver's "unknown"). False, with the row
    untouched, when a scaled position is not finite.
    """
    if not _finite_position(pose, position_scale):
        return False
    for k in range(3):
        row[1 + k] = pose[k] * position_scale if position_scale != 1.0 else pose[k]
    norm = 0.0
    for k in range(3, 7):
        norm += pose[k] * pose[k]
    if norm > 0:
        for k in range(3, 7):
            row[1 + k] = pose[k]
    row[0] = level / levels
    return True


@njit(cache=True)
def driver_rows(  # noqa: PLR0917 - a compiled kernel takes plain positional values
    poses: np.ndarray,
    levels: np.ndarray,
    rows: np.ndarray,
    n_people: int,
    n_joints: int,
    position_scale: float,
    confidence_levels: float,
) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(P, J, 20)`` marker rows and ``(P, J)`` presence of a usual driver message.

    ``poses`` ``(n, 7)`` position and orientation per marker, ``levels`` ``(n,)`` confidence
    levels (NaN: none), ``rows`` each marker's row in the flattened people x joints. Rows hold
    [level / confidence_levels, position * position_scale, orientation] (see ``_fill_row``);
    every other value NaN. The flag is False when a position is not finite: the caller then
    takes the general path, which counts and drops such markers.
    """
    markers = np.full((n_people * n_joints, 20), np.nan)
    present = np.zeros(n_people * n_joints, dtype=np.bool_)
    ok = True
    for i in range(poses.shape[0]):
        if not _fill_row(markers[rows[i]], poses[i], levels[i], position_scale, confidence_levels):
            ok = False
            break
        present[rows[i]] = True
    return markers.reshape(n_people, n_joints, 20), present.reshape(n_people, n_joints), ok


@njit(cache=True, inline="always")
def _u32(buf: np.ndarray, at: int) -> int:
    value = np.int64(buf[at]) | (np.int64(buf[at + 1]) << 8) | (np.int64(buf[at + 2]) << 16)
    return value | (np.int64(buf[at + 3]) << 24)


@njit(cache=True, inline="always")
def _i32(buf: np.ndarray, at: int) -> int:
    value = _u32(buf, at)
    return value - (1 << 32) if value >= (1 << 31) else value


@njit(cache=True, inline="always")
def _string(buf: np.ndarray, start: int, r: int, size: int) -> tuple[int, int, int]:
    """A CDR string at relative offset ``r`` (4-aligned here): its byte span and the next offset.

    The span is (-1, -1) unless the string is plain ASCII without NULs before its terminator
    (what every driver writes; anything else is left to the codec, which names the problem).
    """
    r += -r & 3
    if r + 4 > size:
        return -1, -1, size + 1
    n = _u32(buf, start + r)
    end = r + 4 + n
    if n == 0 or end > size or buf[start + end - 1] != 0:
        return -1, -1, size + 1
    for k in range(start + r + 4, start + end - 1):
        if buf[k] == 0 or buf[k] >= 0x80:
            return -1, -1, size + 1
    return start + r + 4, start + end - 1, end


@njit(cache=True, inline="always")
def _level(buf: np.ndarray, first: int, stop: int) -> tuple[float, bool]:
    """The confidence level written in a marker's text: NaN when empty; False unless digits."""
    if first == stop:
        return math.nan, True
    if stop - first > _MAX_LEVEL_DIGITS:
        return math.nan, False
    value = 0
    for k in range(first, stop):
        digit = np.int64(buf[k]) - 48
        if digit < 0 or digit > 9:
            return math.nan, False
        value = value * 10 + digit
    return float(value), True


@njit(cache=True, inline="always")
def _empty_string(buf: np.ndarray, start: int, r: int, size: int) -> int:
    """Skip an empty CDR string ("": length 1, one NUL); ``size + 1`` when it is not empty."""
    r += -r & 3
    if r + 5 > size or _u32(buf, start + r) != 1 or buf[start + r + 4] != 0:
        return size + 1
    return r + 5


@njit(cache=True, inline="always")
def _sequence(  # noqa: PLR0917 - a compiled kernel takes plain positional values
    buf: np.ndarray, start: int, r: int, size: int, item: int, align: int
) -> int:
    """Skip a CDR sequence of ``item``-byte values aligned to ``align``; ``size + 1`` if cut."""
    r += -r & 3
    if r + 4 > size:
        return size + 1
    n = _u32(buf, start + r)
    r += 4
    if align == 8:
        r += (4 - r) & 7
    r += n * item
    return r if r <= size else size + 1


@njit(cache=True, inline="always")
def _media(buf: np.ndarray, start: int, r: int, size: int) -> int:
    """Skip the texture fields, which drivers leave empty; ``size + 1`` when they are not.

    texture_resource "", texture (stamp 0, frame "", format "", no data), no uv coordinates.
    """
    r = _empty_string(buf, start, r, size)
    if r + 8 > size or _u32(buf, start + r) != 0 or _u32(buf, start + r + 4) != 0:
        return size + 1
    r = _empty_string(buf, start, _empty_string(buf, start, r + 8, size), size)
    for _ in range(2):  # texture data (uint8[]) and uv_coordinates: both empty
        r += -r & 3
        if r + 4 > size or _u32(buf, start + r) != 0:
            return size + 1
        r += 4
    return r


@njit(cache=True, inline="always")
def _marker(  # noqa: PLR0911, PLR0917 - one flat walk over a Marker's fields
    buf: np.ndarray,
    start: int,
    r: int,
    size: int,
    out: int,
    ids: np.ndarray,
    stamps: np.ndarray,
    spans: np.ndarray,
    poses: np.ndarray,
    levels: np.ndarray,
    position_scale: float,
) -> int:
    """Read the marker at relative offset ``r`` into row ``out``; the next offset, or -1.

    Row ``out`` of ``ids``, ``stamps``, ``spans`` (byte spans of frame and namespace),
    ``poses`` (where its 7 pose floats start in ``buf``) and ``levels`` (its confidence level,
    NaN: none). -1 also when the marker is not a usual driver joint (not an ADD, texture or mesh
    fields set, non-ASCII strings, a text that is no level, a position that is not finite):
    the caller leaves such a message to the codec and the bridge.
    """
    r += -r & 3
    if r + 8 > size:
        return -1
    stamps[out] = np.int64(_i32(buf, start + r)) * 1_000_000_000 + _u32(buf, start + r + 4)
    frame_first, frame_stop, r = _string(buf, start, r + 8, size)
    ns_first, ns_stop, r = _string(buf, start, r, size)
    r += -r & 3
    if frame_first < 0 or ns_first < 0 or r + 12 > size:
        return -1
    spans[out, 0], spans[out, 1], spans[out, 2], spans[out, 3] = (
        frame_first, frame_stop, ns_first, ns_stop
    )  # fmt: skip
    ids[out] = _i32(buf, start + r)
    if _i32(buf, start + r + 8) != 0:  # action: not ADD
        return -1
    r += 12
    r += (4 - r) & 7  # the pose is 8-aligned in the payload (which starts at offset 4)
    if r + 105 > size or buf[start + r + 104] > 1:  # pose, scale, colour, lifetime, locked
        return -1
    poses[out] = start + r
    if not _finite_position(buf[start + r : start + r + 24].view(np.float64), position_scale):
        return -1
    r = _sequence(buf, start, r + 105, size, 24, 8)  # points
    r = _sequence(buf, start, r, size, 16, 4)  # colors
    text_first, text_stop, r = _string(buf, start, _media(buf, start, r, size), size)
    r = _empty_string(buf, start, _empty_string(buf, start, r, size), size)  # mesh resource, file
    r += -r & 3
    if text_first < 0 or r + 5 > size or _u32(buf, start + r) != 0 or buf[start + r + 4] > 1:
        return -1  # mesh data empty, mesh_use_embedded_materials a bool
    levels[out], ok = _level(buf, text_first, text_stop)
    return r + 5 if ok else -1


@njit(cache=True)
def driver_messages(
    buf: np.ndarray, starts: np.ndarray, ends: np.ndarray, position_scale: float
) -> tuple[np.ndarray, ...]:
    """Read many driver MarkerArrays (CDR bytes ``buf[starts[m]:ends[m]]``) in one call.

    Returns per message ``first`` ``(M + 1,)`` (message ``m``'s markers are rows
    ``first[m]:first[m + 1]``), ``usual`` ``(M,)``: every marker read as a usual driver joint
    (see ``_marker``) and at least one, and ``mixed`` ``(M,)``: its markers' stamps differ;
    per marker ``ids``, ``stamps`` (ns), ``spans`` ``(N, 4)``, ``poses`` and ``levels`` as
    ``_marker`` writes them. The rows of a message that is not usual mean nothing: the caller
    hands such a message to the codec and the bridge.
    """
    n_messages = starts.size
    first = np.zeros(n_messages + 1, dtype=np.int64)
    for m in range(n_messages):
        start, size = starts[m], ends[m] - starts[m]
        n = 0
        if size >= 8 and buf[start] == 0 and buf[start + 1] == 1:  # the CDR header, LE
            n = _u32(buf, start + 4)
            if n * _MIN_MARKER_BYTES > size - 8:
                n = 0
        first[m + 1] = first[m] + n
    total = first[n_messages]
    ids = np.zeros(total, dtype=np.int32)
    stamps = np.zeros(total, dtype=np.int64)
    spans = np.zeros((total, 4), dtype=np.int64)
    poses = np.zeros(total, dtype=np.int64)
    levels = np.zeros(total)
    usual = np.zeros(n_messages, dtype=np.bool_)
    mixed = np.zeros(n_messages, dtype=np.bool_)
    for m in range(n_messages):
        start, size = starts[m], ends[m] - starts[m]
        r = 8
        for out in range(first[m], first[m + 1]):
            r = _marker(buf, start, r, size, out, ids, stamps, spans, poses, levels,
                        position_scale)  # fmt: skip
            if r < 0:
                break
        usual[m] = first[m + 1] > first[m] and r >= 0 and size - r <= 3
        for out in range(first[m] + 1, first[m + 1] if usual[m] else 0):
            mixed[m] |= stamps[out] != stamps[first[m]]
    return first, usual, mixed, ids, stamps, spans, poses, levels


@njit(cache=True, inline="always")
def _body_joint(
    marker_id: int, n_joints: int, id_stride: int, joint_major: bool, table: np.ndarray
) -> tuple[int, int]:
    """Body and marker id of a driver marker id; marker id -1 when it is no joint of the layout.

    ``table`` maps driver joint index -> marker id (empty: the same), as
    ``DriverBridge._new_id_shape`` reads ids.
    """
    if marker_id < 0:
        return -1, -1
    major, minor = marker_id // id_stride, marker_id % id_stride
    body, joint = (minor, major) if joint_major else (major, minor)
    if table.size == 0:
        return body, joint if joint < n_joints else -1
    return body, table[joint] if joint < table.size else -1


@njit(cache=True, inline="always")
def _count_people(  # noqa: PLR0917 - a compiled kernel takes plain positional values
    ids: np.ndarray,
    first: int,
    stop: int,
    n_joints: int,
    id_stride: int,
    joint_major: bool,
    table: np.ndarray,
) -> int:
    """People of the markers ``first:stop``; -1 unless they are usual.

    Usual: every marker a joint of the layout and (body, joint) strictly increasing, what
    ``_Arrangement`` requires of a usual message.
    """
    people, last = 0, -1
    for i in range(first, stop):
        body, joint = _body_joint(ids[i], n_joints, id_stride, joint_major, table)
        key = body * n_joints + joint
        if joint < 0 or key <= last:
            return -1
        if i == first or key // n_joints != last // n_joints:
            people += 1
        last = key
    return people if stop > first else -1


@njit(cache=True, inline="always")
def _same_bytes(buf: np.ndarray, first: int, stop: int, other: int, other_stop: int) -> bool:
    """Whether ``buf[first:stop]`` and ``buf[other:other_stop]`` hold the same bytes."""
    if stop - first != other_stop - other:
        return False
    for k in range(stop - first):  # noqa: SIM110 - a compiled loop, no generator
        if buf[first + k] != buf[other + k]:
            return False
    return True


@njit(cache=True)
def driver_people(  # noqa: PLR0917 - a compiled kernel takes plain positional values
    buf: np.ndarray,
    parsed: tuple[np.ndarray, ...],
    namespace: np.ndarray,
    n_joints: int,
    id_stride: int,
    joint_major: bool,
    table: np.ndarray,
    position_scale: float,
    confidence_levels: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The people of ``driver_messages``' usual messages (``parsed``), in one set of rows.

    A message makes people here when it is usual, its first marker's namespace is the bytes
    ``buf[namespace[0]:namespace[1]]`` (the one layout of the batch) and its ids make ordered
    people (``_count_people``). Returns ``made`` ``(M,)`` those messages, ``people``
    ``(M + 1,)`` each one's first person (messages ``m`` has ``people[m]:people[m + 1]``),
    ``bodies`` ``(P,)`` body ids, and ``(P, J, 20)`` marker rows with ``(P, J)`` presence,
    rows as ``driver_rows`` writes them.
    """
    first, usual, _, ids, _, spans, poses, levels = parsed
    n_messages = first.size - 1
    made = usual.copy()
    people = np.zeros(n_messages + 1, dtype=np.int64)
    for m in range(n_messages):
        count = 0
        if made[m]:
            count = _count_people(ids, first[m], first[m + 1], n_joints, id_stride, joint_major,
                                  table)  # fmt: skip
            name = spans[first[m]]
            if count < 0 or not _same_bytes(buf, name[2], name[3], namespace[0], namespace[1]):
                made[m], count = False, 0
        people[m + 1] = people[m] + count
    markers = np.full((people[n_messages], n_joints, 20), np.nan)
    present = np.zeros((people[n_messages], n_joints), dtype=np.bool_)
    bodies = np.zeros(people[n_messages], dtype=np.int64)
    for m in range(n_messages):
        person = people[m] - 1
        for i in range(first[m], first[m + 1] if made[m] else 0):
            body, joint = _body_joint(ids[i], n_joints, id_stride, joint_major, table)
            if person < people[m] or body != bodies[person]:
                person += 1
                bodies[person] = body
            pose = buf[poses[i] : poses[i] + 56].view(np.float64)
            _fill_row(markers[person, joint], pose, levels[i], position_scale, confidence_levels)
            present[person, joint] = True
    return made, people, bodies, markers, present
