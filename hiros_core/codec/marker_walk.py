"""The MarkerArray walk (numba): where every field of every marker of many messages lies.

One walk serves the codec and the driver bridge. The codec walks a message of a new shape once
(``marker_array._walk_marker_array``) before its plan exists; the bridge walks a recording's
batch of driver messages (a whole MCAP chunk) in one call (``driver.kernels.driver_messages``).
A message is *regular* when it is well formed and carries no media: no texture, uv coordinates
or mesh, and booleans of 0 or 1. Anything else is left to the codec's field reader, which reads
every field and names what is wrong.

Offsets named ``r`` are relative to a message's first byte; its CDR payload starts at 4, so
4-alignment is ``r``'s own and 8-alignment is ``r - 4``'s. Offsets in the table are absolute
(in ``buf``). The small helpers are inlined (``inline="always"``): called per field of every
marker, their calls cost a third of the walk. Imported at the first call (the rule:
``hiros_core.compiled``); compiled on first use, cached on disk.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = [
    "COLUMNS",
    "EMBEDDED",
    "FRAME",
    "ID",
    "LIFETIME",
    "LOCKED",
    "NAMESPACE",
    "POINTS",
    "POINT_COLORS",
    "POSE",
    "STAMP",
    "TEXT",
    "walk_markers",
]

MIN_MARKER_BYTES = 150
"""A Marker's smallest CDR size: more markers than a message's bytes allow is bad data."""

STAMP = 0
"""Table column: the header stamp, ns."""
FRAME = 1
"""Table columns ``FRAME``, ``FRAME + 1``: the frame id's bytes (no terminator)."""
NAMESPACE = 3
"""Table columns ``NAMESPACE``, ``NAMESPACE + 1``: the namespace's bytes."""
ID = 5
"""Table columns ``ID``, ``ID + 1``, ``ID + 2``: id, type, action."""
POSE = 8
"""Table column: where the 10 float64 of pose (7) and scale (3) start; 16 float32 colour
bytes follow at ``POSE + 80``."""
LIFETIME = 9
"""Table column: the lifetime, ns."""
LOCKED = 10
"""Table column: frame_locked (0 or 1)."""
POINTS = 11
"""Table columns ``POINTS``, ``POINTS + 1``: where the points' float64 start, and how many."""
POINT_COLORS = 13
"""Table columns ``POINT_COLORS``, ``POINT_COLORS + 1``: the same for the float32 colours."""
TEXT = 15
"""Table columns ``TEXT``, ``TEXT + 1``: the text's bytes."""
EMBEDDED = 17
"""Table column: mesh_use_embedded_materials (0 or 1)."""
COLUMNS = 18


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
    """A CDR string at relative offset ``r``: its bytes' span (absolute) and the next offset.

    The next offset is ``size + 1`` when the string is cut or has no terminator.
    """
    r += -r & 3
    if r + 4 > size:
        return -1, -1, size + 1
    n = _u32(buf, start + r)
    end = r + 4 + n
    if n == 0 or end > size or buf[start + end - 1] != 0:
        return -1, -1, size + 1
    return start + r + 4, start + end - 1, end


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
) -> tuple[int, int, int]:
    """A CDR sequence of ``item``-byte values aligned to ``align``.

    Its first value's offset (absolute), its length and the next offset (``size + 1`` if cut).
    """
    r += -r & 3
    if r + 4 > size:
        return 0, 0, size + 1
    n = _u32(buf, start + r)
    r += 4
    if align == 8:
        r += (4 - r) & 7
    if r + n * item > size:
        return 0, 0, size + 1
    return start + r, n, r + n * item


@njit(cache=True, inline="always")
def _media(buf: np.ndarray, start: int, r: int, size: int) -> int:
    """Skip the texture fields, which must be empty; ``size + 1`` when they are not.

    texture_resource "", texture (stamp 0, frame "", format "", no data), no uv coordinates.
    """
    r = _empty_string(buf, start, r, size)
    r += -r & 3  # the stamp (padding bytes are not compared)
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
def _marker(buf: np.ndarray, start: int, r: int, size: int, row: np.ndarray) -> int:
    """Walk the marker at relative offset ``r`` into its table ``row``.

    Returns the next offset, or -1 when the marker is not regular (see the module's docstring).
    """
    r += -r & 3
    if r + 8 > size:
        return -1
    row[STAMP] = np.int64(_i32(buf, start + r)) * 1_000_000_000 + _u32(buf, start + r + 4)
    row[FRAME], row[FRAME + 1], r = _string(buf, start, r + 8, size)
    row[NAMESPACE], row[NAMESPACE + 1], r = _string(buf, start, r, size)
    r += -r & 3
    if r + 12 > size:
        return -1
    for k in range(3):  # id, type, action
        row[ID + k] = _i32(buf, start + r + 4 * k)
    r += 12
    r += (4 - r) & 7  # the pose is 8-aligned in the payload (which starts at offset 4)
    if r + 105 > size or buf[start + r + 104] > 1:  # pose, scale, colour, lifetime, locked
        return -1
    row[POSE] = start + r
    row[LIFETIME] = np.int64(_i32(buf, start + r + 96)) * 1_000_000_000 + _u32(buf, start + r + 100)
    row[LOCKED] = buf[start + r + 104]
    row[POINTS], row[POINTS + 1], r = _sequence(buf, start, r + 105, size, 24, 8)
    row[POINT_COLORS], row[POINT_COLORS + 1], r = _sequence(buf, start, r, size, 16, 4)
    row[TEXT], row[TEXT + 1], r = _string(buf, start, _media(buf, start, r, size), size)
    r = _empty_string(buf, start, _empty_string(buf, start, r, size), size)  # mesh resource, file
    r += -r & 3
    if r + 5 > size or _u32(buf, start + r) != 0 or buf[start + r + 4] > 1:
        return -1  # mesh data empty, mesh_use_embedded_materials a bool
    row[EMBEDDED] = buf[start + r + 4]
    return r + 5


@njit(cache=True)
def walk_markers(
    buf: np.ndarray, starts: np.ndarray, ends: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Walk many MarkerArrays (CDR bytes ``buf[starts[m]:ends[m]]``) in one call.

    Returns ``first`` ``(M + 1,)`` (message ``m``'s markers are rows ``first[m]:first[m + 1]``),
    ``regular`` ``(M,)`` (message ``m`` was walked to its end: see the module's docstring) and
    the ``(N, COLUMNS)`` int64 table of the markers' fields (the column constants). The rows
    of a message that is not regular mean nothing.
    """
    n_messages = starts.size
    first = np.zeros(n_messages + 1, dtype=np.int64)
    header = np.zeros(n_messages, dtype=np.bool_)
    for m in range(n_messages):
        start, size = starts[m], ends[m] - starts[m]
        n = 0
        if size >= 8 and buf[start] == 0 and buf[start + 1] == 1:  # the CDR header, LE
            n = _u32(buf, start + 4)
            header[m] = n * MIN_MARKER_BYTES <= size - 8
            if not header[m]:
                n = 0
        first[m + 1] = first[m] + n
    table = np.zeros((first[n_messages], COLUMNS), dtype=np.int64)
    regular = np.zeros(n_messages, dtype=np.bool_)
    for m in range(n_messages):
        start, size = starts[m], ends[m] - starts[m]
        r = 8
        for out in range(first[m], first[m + 1]):
            r = _marker(buf, start, r, size, table[out])
            if r < 0:
                break
        regular[m] = header[m] and r >= 0 and size - r <= 3
    return first, regular, table
