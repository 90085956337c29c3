"""A fast MCAP writer: chunks built in one buffer, compressed and written by a helper thread.

The ``mcap`` library's ``Writer`` compresses every chunk with zstd level 3 in the calling
thread and builds each message record through several small writes; on ``hiros run``'s output
(megabytes of CDR per recording second) that was most of the writing time. Here:

* the open chunk is one preallocated buffer: a message record is its ``struct`` header packed
  in place and its payload copied after it, or written there directly by an encoder
  (``reserve`` then ``commit``: ``RecordingWriter.write_group`` encodes SkeletonGroups
  straight into the chunk), so no per-message ``bytes`` object is made, kept or joined;
* a full chunk goes to one background thread that compresses it (zstd at a fast level by
  default, ``ZSTD_LEVEL``; or lz4), computes its CRC and writes
  it with its message indexes, then hands the buffer back for a later chunk (reused buffers
  are already mapped: no page faults per chunk). zstd, lz4, crc32 and file writes release
  the GIL, so this runs beside the caller's work on another core;
* records other than messages (schemas, channels, metadata, the summary) use the ``mcap``
  library's record classes, so the layout follows the MCAP specification as that library
  implements it (summary with repeated schemas and channels, statistics, metadata and chunk
  indexes and summary offsets, all CRCs), which ``ros2 bag`` (rosbag2_storage_mcap) and
  Foxglove read.

The file's bytes depend only on the messages written and the settings: deterministic.
"""

from __future__ import annotations

import queue
import struct
import threading
from collections.abc import Callable
from typing import IO

import numpy as np
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from hiros_core.recording.checksum import crc32

__all__ = ["COMPRESSIONS", "McapWriter"]

MAGIC = b"\x89MCAP0\r\n"
COMPRESSIONS = ("zstd", "lz4", "none")
ZSTD_LEVEL = -3
"""zstd level of the chunks: files about as small as at the ``mcap`` library's level 3, for a
fraction of its CPU (figures: docs/architecture.md, "Figures out of the docstrings")."""

_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
_MESSAGE_FIXED = _MESSAGE.size - 9  # record content before the payload
_FOOTER_CRC_HEAD = struct.Struct("<BQQQ")
# opcode, record length, start, end, uncompressed size, uncompressed crc, compression length
_CHUNK_HEAD = struct.Struct("<BQQQQII")
_U64 = struct.Struct("<Q")
_PENDING_CHUNKS = 4  # chunks queued for the writer thread before add_message waits
_SLACK = 1 << 20  # buffer bytes past chunk_size: a chunk closes only once it exceeds the size


def _compressor(compression: str, level: int) -> tuple[str, Callable[[bytes], bytes]]:
    """The chunk record's compression name and the function compressing a whole chunk."""
    if compression == "zstd":
        import zstandard

        return "zstd", zstandard.ZstdCompressor(level=level).compress
    if compression == "lz4":
        import lz4.frame

        return "lz4", lz4.frame.compress
    return "", bytes


def _record(record: object) -> bytes:
    builder = RecordBuilder()
    record.write(builder)  # type: ignore[attr-defined]
    return builder.end()


class McapWriter:
    """Append-only MCAP writer (profile ``ros2`` by default) over a binary stream.

    Args:
        stream: where the file goes (left open by ``finish``).
        chunk_size: uncompressed bytes per chunk (a chunk is closed once it exceeds this).
        compression: ``zstd``, ``lz4`` or ``none``.
        level: zstd level (negative: faster, larger).

    """

    def __init__(
        self,
        stream: IO[bytes],
        *,
        chunk_size: int = 4 << 20,
        compression: str = "zstd",
        level: int = ZSTD_LEVEL,
    ) -> None:
        if compression not in COMPRESSIONS:
            msg = f"unknown MCAP compression {compression!r}: use zstd, lz4 or none"
            raise ValueError(msg)
        self.stream = stream
        self.chunk_size = chunk_size
        self.compression, self._compress = _compressor(compression, level)
        self.schemas: list[Schema] = []
        self.channels: list[Channel] = []
        self.channel_counts: dict[int, int] = {}
        self.message_count = 0
        self.start_time = 0
        self.end_time = 0
        self.chunk_indexes: list[ChunkIndex] = []
        self._metadata: list[Metadata] = []
        self._free: queue.SimpleQueue[bytearray] = queue.SimpleQueue()  # written buffers
        self._reset_chunk()
        self._jobs: queue.Queue[tuple | None] = queue.Queue(maxsize=_PENDING_CHUNKS)
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._position = 0

    def _reset_chunk(self) -> None:
        try:
            buffer = self._free.get_nowait()
        except queue.Empty:
            buffer = bytearray(self.chunk_size + _SLACK)
        self._use_buffer(buffer)
        self._chunk_length = 0
        self._chunk_messages = 0
        self._chunk_start = 0
        self._chunk_end = 0
        self._indexes: dict[int, list[tuple[int, int]]] = {}

    def _use_buffer(self, buffer: bytearray) -> None:
        self._buffer = buffer
        self.buffer = np.frombuffer(buffer, dtype=np.uint8)  # for encoders: see ``reserve``

    def start(self, profile: str = "ros2", library: str = "hiros") -> None:
        """Write the magic and the header record."""
        self._write(MAGIC + _record(Header(profile=profile, library=library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """A new schema; returns its id (1, 2, ...)."""
        schema = Schema(id=len(self.schemas) + 1, name=name, encoding=encoding, data=data)
        self.schemas.append(schema)
        self._append(_record(schema))
        return schema.id

    def register_channel(
        self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str]
    ) -> int:
        """A new channel; returns its id (1, 2, ...)."""
        channel = Channel(
            id=len(self.channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=metadata,
        )
        self.channels.append(channel)
        self.channel_counts[channel.id] = 0
        self._append(_record(channel))
        return channel.id

    def add_metadata(self, name: str, metadata: dict[str, str]) -> None:
        """A metadata record (name and string pairs), written after the chunks by ``finish``.

        rosbag2 keeps its bag metadata so, in a record named ``rosbag2``; the summary indexes it.
        """
        self._metadata.append(Metadata(name=name, metadata=metadata))

    def _append(self, record: bytes) -> None:
        """Copy a whole record (schema, channel) into the open chunk."""
        at = self._room(len(record))
        self._buffer[at : at + len(record)] = record
        self._chunk_length = at + len(record)

    def _room(self, size: int) -> int:
        """Where ``size`` more bytes go in the open chunk (its buffer grows if they do not fit)."""
        at = self._chunk_length
        if at + size > len(self._buffer):  # a message larger than the slack: rare
            grown = bytearray(max(2 * len(self._buffer), at + size + _SLACK))
            grown[:at] = memoryview(self._buffer)[:at]
            self._use_buffer(grown)
        return at

    def add_message(
        self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int
    ) -> None:
        """Append one message to the open chunk; a full chunk goes to the writer thread."""
        if not isinstance(data, bytes | bytearray):
            data = memoryview(data).cast("B")  # any contiguous buffer, counted in bytes
        size = len(data)
        at = self.reserve(size)
        self._buffer[at : at + size] = data
        self.commit(channel_id, log_time, size, publish_time, sequence)

    def reserve(self, size: int) -> int:
        """Offset in ``self.buffer`` where the next message's ``size`` payload bytes go.

        Write the payload there, then ``commit`` it; until then nothing is recorded, so an
        encoder that fails half way leaves the file as it was. ``self.buffer`` may be
        another array after the next ``reserve``.
        """
        return self._room(_MESSAGE.size + size) + _MESSAGE.size

    def commit(
        self, channel_id: int, log_time: int, size: int, publish_time: int, sequence: int
    ) -> None:
        """Record the message whose ``size`` bytes were written where ``reserve`` said."""
        if self._chunk_messages:
            if log_time < self._chunk_start:
                self._chunk_start = log_time
            elif log_time > self._chunk_end:
                self._chunk_end = log_time
        else:
            self._chunk_start = self._chunk_end = log_time
        if self.message_count:
            if log_time < self.start_time:
                self.start_time = log_time
            elif log_time > self.end_time:
                self.end_time = log_time
        else:
            self.start_time = self.end_time = log_time
        at = self._chunk_length
        index = self._indexes.get(channel_id)
        if index is None:
            index = self._indexes[channel_id] = []
        index.append((log_time, at))
        _MESSAGE.pack_into(
            self._buffer, at, Opcode.MESSAGE, _MESSAGE_FIXED + size, channel_id, sequence,
            log_time, publish_time,
        )  # fmt: skip
        self._chunk_length = at + _MESSAGE.size + size
        self._chunk_messages += 1
        self.message_count += 1
        self.channel_counts[channel_id] += 1
        if self._chunk_length > self.chunk_size:
            self._close_chunk()

    def _close_chunk(self) -> None:
        if not self._chunk_messages:
            return
        job = (
            self._buffer, self._chunk_length, self._chunk_start, self._chunk_end, self._indexes
        )  # fmt: skip
        self._reset_chunk()
        if self._thread is None:
            self._thread = threading.Thread(target=self._work, name="mcap-writer", daemon=True)
            self._thread.start()
        self._raise_error()
        self._jobs.put(job)

    def _work(self) -> None:
        """Writer thread: compress, checksum and write queued chunks in order."""
        while (job := self._jobs.get()) is not None:
            if self._error is None:
                try:
                    self._write_chunk(*job)
                except BaseException as exc:  # handed to the caller by _raise_error
                    self._error = exc

    def _write_chunk(
        self,
        buffer: bytearray,
        size: int,
        start: int,
        end: int,
        indexes: dict[int, list[tuple[int, int]]],
    ) -> None:
        # One call per step, each releasing the GIL for its whole length (crc32, the
        # compressor, the file write), so the producing thread keeps its core.
        data = memoryview(buffer)[:size]
        crc = crc32(data)
        compressed = self._compress(data)
        data.release()
        self._free.put(buffer)
        name = self.compression.encode()
        length = _CHUNK_HEAD.size - 9 + len(name) + 8 + len(compressed)
        head = _CHUNK_HEAD.pack(Opcode.CHUNK, length, start, end, size, crc, len(name))
        chunk_at = self._position
        self._write(head + name + _U64.pack(len(compressed)))
        self._write(compressed)
        index_offsets, records = {}, bytearray()
        for channel_id, entries in indexes.items():
            index_offsets[channel_id] = self._position + len(records)
            records += _record(MessageIndex(channel_id=channel_id, records=entries))
        self._write(records)
        self.chunk_indexes.append(
            ChunkIndex(
                message_start_time=start,
                message_end_time=end,
                chunk_start_offset=chunk_at,
                chunk_length=len(head) + len(name) + 8 + len(compressed),
                message_index_offsets=index_offsets,
                message_index_length=len(records),
                compression=self.compression,
                compressed_size=len(compressed),
                uncompressed_size=size,
            )
        )

    def _write(self, data: bytes | bytearray) -> None:
        self.stream.write(data)
        self._position += len(data)

    def _raise_error(self) -> None:
        """Raise the writer thread's error (it stays: the file cannot be finished after it)."""
        if self._error is not None:
            raise self._error

    def _drain(self) -> None:
        """Wait until the writer thread has written every queued chunk."""
        if self._thread is not None:
            self._jobs.put(None)
            self._thread.join()
            self._thread = None
        self._raise_error()

    def abort(self) -> None:
        """Stop the writer thread without finishing the file (after an error)."""
        if self._thread is not None:
            self._error = self._error or RuntimeError("aborted")
            self._jobs.put(None)
            self._thread.join()
            self._thread = None

    def finish(self) -> None:
        """Write the last chunk, the data end, the summary and the footer (stream left open)."""
        self._close_chunk()
        self._drain()
        metadata_indexes = []
        for metadata in self._metadata:
            record = _record(metadata)
            metadata_indexes.append(
                MetadataIndex(offset=self._position, length=len(record), name=metadata.name)
            )
            self._write(record)
        self._write(_record(DataEnd(data_section_crc=0)))
        summary_start = self._position
        summary, offsets = bytearray(), []
        groups = [
            (Opcode.SCHEMA, self.schemas),
            (Opcode.CHANNEL, self.channels),
            (Opcode.STATISTICS, [self._statistics()]),
            (Opcode.METADATA_INDEX, metadata_indexes),
            (Opcode.CHUNK_INDEX, self.chunk_indexes),
        ]
        for opcode, records in groups:
            if not records:
                continue
            group_start = len(summary)
            for record in records:
                summary += _record(record)
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode,
                    group_start=summary_start + group_start,
                    group_length=len(summary) - group_start,
                )
            )
        offset_start = summary_start + len(summary)
        for offset in offsets:
            summary += _record(offset)
        crc = crc32(summary)
        crc = crc32(_FOOTER_CRC_HEAD.pack(Opcode.FOOTER, 20, summary_start, offset_start), crc)
        footer = Footer(summary_start=summary_start, summary_offset_start=offset_start,
                        summary_crc=crc)  # fmt: skip
        self._write(bytes(summary) + _record(footer) + MAGIC)

    def _statistics(self) -> Statistics:
        return Statistics(
            message_count=self.message_count,
            schema_count=len(self.schemas),
            channel_count=len(self.channels),
            attachment_count=0,
            metadata_count=len(self._metadata),
            chunk_count=len(self.chunk_indexes),
            message_start_time=self.start_time,
            message_end_time=self.end_time,
            channel_message_counts=dict(self.channel_counts),
        )
