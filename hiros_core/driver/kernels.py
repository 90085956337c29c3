"""Compiled (numba) forms of the bridge's usual frame, same rows bit for bit as the numpy path.

The driver's usual message (every marker an ADD of a known joint, ids in increasing order, as
the ids of earlier messages showed) turns into marker rows by a dozen small numpy calls per
message in ``DriverBridge._kept_markers``/``_skeletons``; ``driver_rows`` does it in one call.
``driver_messages`` goes further for a recording: it walks the driver's MarkerArray CDR bytes
of many messages at once (a whole MCAP chunk) with the codec's walk (``codec.marker_walk``),
and ``driver_people`` turns the usual ones straight into marker rows, so that decoding costs
no Python work per marker and next to none per message. The small helpers are inlined
(``inline="always"``). Always the bridge's path for usual messages; imported at the bridge's
first call, compiled on first use and cached on disk (the rule: ``hiros_core.compiled``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hiros_core.codec import marker_walk
from hiros_core.codec.marker_walk import FRAME, ID, NAMESPACE, POSE, STAMP, TEXT, walk_markers
from hiros_core.compiled import refresh_stale_caches

__all__ = ["driver_messages", "driver_people", "driver_rows"]

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
def _ascii(buf: np.ndarray, first: int, stop: int) -> bool:
    """Whether ``buf[first:stop]`` is plain ASCII without NULs (what every driver writes)."""
    for k in range(first, stop):  # noqa: SIM110 - a compiled loop, no generator
        if buf[k] == 0 or buf[k] >= 0x80:
            return False
    return True


@njit(cache=True)
def _usual_markers(
    buf: np.ndarray, walked: tuple[np.ndarray, np.ndarray, np.ndarray], position_scale: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which walked messages are usual driver messages, which of those mix stamps, and levels.

    Usual: regular (``walk_markers``), at least one marker, and every marker an ADD with
    ASCII frame and namespace, a text that is a level (see ``_level``) and a finite scaled
    position. Returns ``usual`` ``(M,)``, ``mixed`` ``(M,)`` (its markers' stamps differ) and
    per marker ``levels`` (NaN: none).
    """
    first, regular, table = walked
    n_messages = first.size - 1
    usual = np.zeros(n_messages, dtype=np.bool_)
    mixed = np.zeros(n_messages, dtype=np.bool_)
    levels = np.full(table.shape[0], np.nan)
    for m in range(n_messages):
        usual[m] = regular[m] and first[m + 1] > first[m]
        for i in range(first[m], first[m + 1] if usual[m] else 0):
            row = table[i]
            pose = buf[row[POSE] : row[POSE] + 24].view(np.float64)
            levels[i], level_ok = _level(buf, row[TEXT], row[TEXT + 1])
            if not (
                row[ID + 2] == 0  # action ADD
                and _ascii(buf, row[FRAME], row[FRAME + 1])
                and _ascii(buf, row[NAMESPACE], row[NAMESPACE + 1])
                and level_ok
                and _finite_position(pose, position_scale)
            ):
                usual[m] = False
                break
            mixed[m] |= row[STAMP] != table[first[m], STAMP]
        if not usual[m]:
            mixed[m] = False
    return usual, mixed, levels


def driver_messages(
    buf: np.ndarray, starts: np.ndarray, ends: np.ndarray, position_scale: float
) -> tuple[np.ndarray, ...]:
    """Read many driver MarkerArrays (CDR bytes ``buf[starts[m]:ends[m]]``) in two calls.

    The codec's walk (``codec.marker_walk.walk_markers``) finds every field; ``_usual_markers``
    picks the usual driver messages. Returns per message ``first`` ``(M + 1,)`` (message
    ``m``'s markers are rows ``first[m]:first[m + 1]``), ``usual`` ``(M,)`` and ``mixed``
    ``(M,)`` (its markers' stamps differ); per marker ``ids``, ``stamps`` (ns), ``spans``
    ``(N, 4)`` (the byte spans of frame and namespace), ``poses`` (where its 7 pose floats
    start in ``buf``) and ``levels`` (NaN: none). The rows of a message that is not usual mean
    nothing: the caller hands such a message to the codec and the bridge.
    """
    walked = walk_markers(buf, starts, ends)
    usual, mixed, levels = _usual_markers(buf, walked, position_scale)
    first, _, table = walked
    return (
        first, usual, mixed, table[:, ID].copy(), table[:, STAMP].copy(),
        table[:, FRAME : NAMESPACE + 2].copy(), table[:, POSE].copy(), levels,
    )  # fmt: skip


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


# the kernels above read the walk's column numbers, which numba compiles in as constants
refresh_stale_caches(globals(), marker_walk)
