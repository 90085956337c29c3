"""The sizes hiros reads at most, so that a hostile or broken input cannot take all memory.

Every reader checks these before it allocates: a recording's chunk is not decompressed, and
a message not decoded, when the sizes written in it are past a limit. What is over a limit
is dropped with a counted reason (``oversized_chunk``, ``oversized_message``,
``too_many_markers``, ``too_many_bodies``), never allocated. The YAML limits (file size,
nesting, aliases) are in ``hiros_core.safe_yaml``.

The limits are far above what real sensors produce: an Azure Kinect reports a few people
of 32 joints each (a driver MarkerArray of ~200 markers, ~60 KB), and ``ros2 bag`` writes
MCAP chunks of 4 MiB by default (a chunk holding one 4K colour image is ~33 MB).
"""

from __future__ import annotations

import numpy as np

from hiros_core.errors import CodecError

__all__ = [
    "MAX_BODIES",
    "MAX_CHUNK_BYTES",
    "MAX_MARKERS",
    "MAX_MESSAGE_BYTES",
    "MAX_POSITION_M",
    "OverLimitError",
    "check_marker_array",
    "check_skeleton_group",
    "marker_counts",
]

MAX_CHUNK_BYTES = 128 << 20
"""Largest decompressed MCAP chunk read (its records), bytes."""
MAX_MESSAGE_BYTES = 64 << 20
"""Largest message read from a recording, bytes."""
MAX_BODIES = 64
"""Most skeletons (bodies, people) in one SkeletonGroup or one driver frame."""
MAX_MARKERS = 4096
"""Most markers in one driver MarkerArray (64 bodies of 64 joints)."""

MAX_POSITION_M = 1e4
"""Largest |coordinate| of a joint in the world frame, metres (depth cameras see ~10 m, and a
calibration places a camera within 1 km): a joint past it is marked absent and counted."""

_HEADER = 4  # CDR encapsulation header: 0, 1 (little endian) or 0, 0 (big endian), options


class OverLimitError(CodecError):
    """A message whose counts are past one of the limits; ``reason`` is its drop reason."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


def _u32(data: bytes | bytearray | memoryview, at: int) -> int:
    """The uint32 at ``at`` (payload-relative after the header), in the message's byte order."""
    view = memoryview(data)
    if view.nbytes < _HEADER + at + 4:
        return 0  # too short to hold the count: the decoder rejects it
    order = "little" if view[1] else "big"
    return int.from_bytes(view[_HEADER + at : _HEADER + at + 4], order)


def check_marker_array(data: bytes | bytearray | memoryview) -> None:
    """Refuse a MarkerArray of more than ``MAX_MARKERS`` markers, before decoding it.

    Raises:
        OverLimitError: ``too_many_markers``.

    """
    count = _u32(data, 0)  # the markers sequence's length is the first field
    if count > MAX_MARKERS:
        msg = f"a MarkerArray of {count} markers (at most {MAX_MARKERS} are read)"
        raise OverLimitError(msg, "too_many_markers")


def marker_counts(buffer: bytes | memoryview, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """``(n,)`` markers of each MarkerArray ``buffer[starts[i]:ends[i]]`` (0 when too short)."""
    raw = np.frombuffer(buffer, dtype=np.uint8)
    counts = np.zeros(len(starts), dtype=np.int64)
    whole = (ends - starts) >= _HEADER + 4
    at = starts[whole].astype(np.int64)
    if not len(at):
        return counts
    digits = raw[at[:, None] + _HEADER + np.arange(4)].astype(np.int64)
    little = raw[at + 1] != 0
    weights = np.where(little[:, None], 256 ** np.arange(4), 256 ** np.arange(3, -1, -1))
    counts[whole] = (digits * weights).sum(axis=1)
    return counts


def check_skeleton_group(data: bytes | bytearray | memoryview) -> None:
    """Refuse a SkeletonGroup of more than ``MAX_BODIES`` skeletons, before decoding it.

    The count follows the header: stamp (8 bytes), then ``frame_id`` (uint32 length and its
    characters), padded to 4 bytes.

    Raises:
        OverLimitError: ``too_many_bodies``.

    """
    frame_length = _u32(data, 8)
    at = 12 + frame_length
    count = _u32(data, at + (-at % 4))
    if count > MAX_BODIES:
        msg = f"a SkeletonGroup of {count} skeletons (at most {MAX_BODIES} are read)"
        raise OverLimitError(msg, "too_many_bodies")
