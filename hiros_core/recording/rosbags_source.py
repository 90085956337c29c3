"""sqlite3 (``.db3``) and ROS 1 bags, read with ``rosbags``' ``AnyReader``.

ROS 1 messages are converted to ROS 2 CDR of the ROS 2 Jazzy type of the same name (a ROS 1
header's ``seq`` goes, newer fields get defaults), so every consumer sees one wire format.
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from hiros_core.errors import RecordingError
from hiros_core.limits import MAX_CHUNK_BYTES
from hiros_core.recording.messages import RecordedMessage, Source
from hiros_core.recording.msgdefs import normalize_msgtype


def _bounded_ros1_chunk(decompress: Callable[[bytes, int], bytes]) -> Callable[[bytes], bytes]:
    """A ROS 1 chunk decompressor that inflates at most ``MAX_CHUNK_BYTES``.

    ``rosbags`` inflates a bag's chunks whole, whatever they hold; past the limit the chunk
    is refused (the reader then stops there, as at any damaged part).
    """

    def bounded(data: bytes) -> bytes:
        records = decompress(data, MAX_CHUNK_BYTES + 1)
        if len(records) > MAX_CHUNK_BYTES:
            msg = f"a chunk decompresses to more than the {MAX_CHUNK_BYTES} bytes read"
            raise RecordingError(msg)
        return records

    return bounded


def _bound_ros1_chunks() -> None:
    """Have ``rosbags`` decompress ROS 1 chunks within the limit (its table of decompressors)."""
    import bz2

    import lz4.frame
    from rosbags.rosbag1 import reader as rosbag1

    rosbag1.decompressors.update(
        bz2=_bounded_ros1_chunk(lambda data, n: bz2.BZ2Decompressor().decompress(data, n)),
        lz4=_bounded_ros1_chunk(
            lambda data, n: lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=n)
        ),
    )


class RosbagsSource(Source):
    """A ``.db3`` file, a sqlite3 rosbag2 folder, or a ROS 1 bag, through ``AnyReader``."""

    def __init__(self, path: Path) -> None:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore

        _bound_ros1_chunks()
        self.path = path
        self.reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY))
        try:
            self.reader.open()
        except (AnyReaderError, OSError, ValueError, KeyError) as exc:
            msg = f"cannot read recording {path}: {exc}{_bag_advice(path, exc)}"
            raise RecordingError(msg) from exc
        except Exception as exc:  # rosbags' storage errors have no common base
            msg = f"cannot read recording {path}: {type(exc).__name__}: {exc}"
            raise RecordingError(msg) from exc
        self.topics = {c.topic: normalize_msgtype(c.msgtype) for c in self.reader.connections}
        self._converters: dict[str, Callable[[bytes], bytes]] = {}

    def _to_cdr(self, msgtype: str) -> Callable[[bytes], bytes]:
        """ROS 1 bytes -> ROS 2 Jazzy CDR bytes of the same type (built once per type)."""
        found = self._converters.get(msgtype)
        if found is None:
            found = self._converters[msgtype] = _ros1_converter(self.reader.typestore, msgtype)
        return found

    def messages(self, topics: set[str] | None) -> Iterator[RecordedMessage]:
        """The messages of ``topics`` (None: all), in log-time order, as ROS 2 CDR."""
        connections = [c for c in self.reader.connections if topics is None or c.topic in topics]
        if not connections:
            return
        try:
            for connection, timestamp, raw in self.reader.messages(connections=connections):
                msgtype = normalize_msgtype(connection.msgtype)
                data = bytes(raw) if self.reader.is2 else self._to_cdr(msgtype)(raw)
                yield RecordedMessage(connection.topic, msgtype, timestamp, data)
        except Exception as exc:  # a damaged sqlite file or bag chunk
            msg = f"cannot read recording {self.path} past a damaged part: {exc}"
            raise RecordingError(msg) from exc

    def close(self) -> None:
        """Close the bag."""
        with contextlib.suppress(Exception):
            self.reader.close()


REINDEX = (
    "a ROS 1 recorder stopped without closing the bag (a .bag.active file) leaves no index; "
    "ROS 1's `rosbag reindex` writes it, then the bag can be read"
)


def _bag_advice(path: Path, error: Exception) -> str:
    """What to do about a ROS 1 bag whose index cannot be read (else nothing)."""
    if path.suffix != ".bag" or "index" not in str(error).lower():
        return ""
    return f". {REINDEX[0].upper()}{REINDEX[1:]}"


def _ros1_converter(bag_store: Any, msgtype: str) -> Callable[[bytes], bytes]:
    """A function turning ROS 1 bytes of ``msgtype`` into ROS 2 Jazzy CDR bytes."""
    from rosbags.convert.converter import generate_message_converter
    from rosbags.typesys import Stores, get_typestore

    target = get_typestore(Stores.ROS2_JAZZY)
    if msgtype not in target.fielddefs:
        target.register({k: v for k, v in bag_store.fielddefs.items() if k not in target.fielddefs})
    with contextlib.redirect_stdout(io.StringIO()):  # rosbags prints "will be migrated"
        convert = generate_message_converter(
            bag_store, target, msgtype, msgtype, {}, src_is2=False, dst_is2=True
        )
    return lambda raw: bytes(convert(raw))
