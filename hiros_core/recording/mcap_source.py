"""Our MCAP reader: one file through its chunk index, or straight through when it is cut.

Each chunk is read and decompressed once and its message records located without a Python
object per message, in the order the ``mcap`` library's reader gives (log time, then chunk
position, then position in the chunk). A file without a valid summary (the recorder was killed)
is read straight through by the ``mcap`` library, in file order, up to its last complete record,
and then the whole messages at the start of a chunk the file's end cuts (zstd and lz4
decompress as a stream). Each chunk is checked against its CRC; a damaged chunk is skipped and
counted, and reading goes on after it.
"""

from __future__ import annotations

import contextlib
import io
import os
import struct
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hiros_core.errors import RecordingError
from hiros_core.limits import MAX_CHUNK_BYTES, MAX_MESSAGE_BYTES
from hiros_core.recording.checksum import crc32
from hiros_core.recording.messages import MessageBatch, RecordedMessage, Source
from hiros_core.recording.msgdefs import normalize_msgtype


class McapSource(Source):
    """A single MCAP file, read through its index, or straight through when truncated."""

    def __init__(self, path: Path, drops: Counter[str], problems: list[str]) -> None:
        from mcap.exceptions import McapError
        from mcap.reader import SeekingReader

        self.path = path
        self.drops = drops
        self._scratch = bytearray()  # chunk records of ``transient`` batches
        self.problems = problems
        try:
            self.stream: Any = _BoundedFile(path)
        except OSError as exc:
            msg = f"cannot open recording {path}: {exc}"
            raise RecordingError(msg) from exc
        self.summary = None
        self._salvaged = 0  # messages read from the start of a chunk cut by the file's end
        damage = ""  # what is wrong with the summary, if anything
        try:
            self.reader = SeekingReader(self.stream)
            self.summary = self.reader.get_summary()
        except (McapError, ValueError, OverflowError, struct.error, OSError) as exc:
            damage = f"{type(exc).__name__}: {exc}"
            if self.stream.seek(0, io.SEEK_END) < 8:
                self.stream.close()
                msg = f"{path} is not an MCAP file (too short: {exc})"
                raise RecordingError(msg) from None
            self.stream.seek(0)
            if self.stream.read(8) != b"\x89MCAP0\r\n":
                self.stream.close()
                msg = f"{path} is not an MCAP file (no MCAP magic bytes at its start)"
                raise RecordingError(msg) from None
        if self.summary is not None and not self._summary_intact():
            self.summary = None  # its chunk index may point anywhere: read straight through
            damage = "its CRC does not match"
        if self.summary is not None and self.summary.chunk_indexes:
            self.topics = {
                c.topic: normalize_msgtype(self.summary.schemas[c.schema_id].name)
                for c in self.summary.channels.values()
                if c.schema_id in self.summary.schemas
            }
        else:
            self.topics = {}
            self._data_end = False
            for _ in self._scan(None, collect_only=True):
                pass
            if not self.topics and not self._data_end:
                self.stream.close()
                msg = (
                    f"{path} ends early or is damaged at byte {self._stopped_at}, before any "
                    "topic is defined in it: nothing in it can be read"
                )
                raise RecordingError(msg)
            if damage and self._data_end:  # else the file ends early, which _scan reports
                self.problems.append(
                    f"{path}: its summary (the index at its end) is damaged ({damage}); "
                    "read it straight through"
                )

    def _summary_intact(self) -> bool:
        """Whether the summary section and footer match the footer's CRC (when it has one)."""
        end = self.stream.seek(0, io.SEEK_END)
        self.stream.seek(end - 8 - _FOOTER.size)
        footer = self.stream.read(_FOOTER.size)
        if len(footer) < _FOOTER.size:
            return False
        _, _, summary_start, _, crc = _FOOTER.unpack(footer)
        if not crc:
            return True
        self.stream.seek(summary_start)
        return crc32(self.stream.read(end - 8 - 4 - summary_start)) == crc

    def _scan(self, topics: set[str] | None, *, collect_only: bool = False) -> Iterator[Any]:
        """Records straight through the file, stopping cleanly at the first unreadable byte."""
        from mcap.exceptions import McapError
        from mcap.records import Channel, DataEnd, Footer, Message, Schema
        from mcap.stream_reader import StreamReader

        self.stream.seek(0)
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        count = 0
        chunked = StreamReader(self.stream, skip_magic=False, emit_chunks=True).records
        records = self._unchunked(chunked, count_damage=not collect_only)
        try:
            for record in records:
                if isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    msgtype = normalize_msgtype(schemas.get(record.schema_id, "unknown/Unknown"))
                    channels[record.id] = (record.topic, msgtype)
                    self.topics.setdefault(record.topic, msgtype)
                elif isinstance(record, Message) and not collect_only:
                    topic, msgtype = channels.get(record.channel_id, ("", ""))
                    if not topic:
                        self.drops["unknown_channel"] += 1
                    elif len(record.data) > MAX_MESSAGE_BYTES:
                        self.drops["oversized_message"] += 1
                    elif topics is None or topic in topics:
                        count += 1
                        yield RecordedMessage(topic, msgtype, record.log_time, record.data)
                elif isinstance(record, (DataEnd, Footer)):  # the summary holds no messages
                    self._data_end = True
                    return
        except (McapError, ValueError, OverflowError, struct.error, EOFError, OSError) as exc:
            self._stopped_at = self.stream.tell()
            if not collect_only:
                self.drops["truncated"] += 1
                salvaged = (
                    f", {self._salvaged} of them from the chunk the end cuts"
                    if self._salvaged
                    else ""
                )
                self.problems.append(
                    f"{self.path} ends early or is damaged at byte {self.stream.tell()} "
                    f"({type(exc).__name__}: {exc}); read {count} messages before that"
                    f"{salvaged} (a recorder that was stopped without closing the file leaves "
                    "this)"
                )

    def _unchunked(self, records: Iterable[Any], *, count_damage: bool) -> Iterator[Any]:
        """``records`` with each chunk replaced by its records, checked by the chunk's CRC.

        A damaged chunk is skipped (its messages are lost, counted once as ``damaged_chunk``)
        and reading goes on with the next record: the chunk's length is outside its data.
        """
        from mcap.records import Chunk, Message

        start = self.stream.tell()  # where the record the next step reads begins
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except Exception:  # the file ends early or is damaged here: _scan reports it
                salvaged = _whole_records(self._cut_chunk_records(start))
                self._salvaged = sum(isinstance(r, Message) for r in salvaged)
                yield from salvaged
                raise
            if not isinstance(record, Chunk):
                yield record
            else:
                try:
                    inner = self._chunk_of_records(record, start)
                except _OversizedChunkError as exc:
                    if count_damage:
                        self.drops["oversized_chunk"] += 1
                        self.problems.append(f"{exc}; skipped its messages, read on after it")
                except Exception as exc:  # mcap, zstandard and lz4 raise their own error types
                    if count_damage:
                        self.drops["damaged_chunk"] += 1
                        self.problems.append(
                            f"{self.path}: a chunk before byte {self.stream.tell()} is damaged "
                            f"({type(exc).__name__}: {exc}); skipped its messages, read on "
                            "after it"
                        )
                else:
                    yield from inner
            start = self.stream.tell()

    def _chunk_of_records(self, chunk: Any, offset: int) -> list[Any]:
        """The records of a chunk read straight through, decompressed within the limits.

        ``breakup_chunk`` itself would inflate whatever the compressed frame claims.
        """
        from mcap.records import Chunk
        from mcap.stream_reader import breakup_chunk

        size = chunk.uncompressed_size
        records = self._decompress(chunk.compression, memoryview(chunk.data), size, offset)
        if chunk.uncompressed_crc and crc32(records) != chunk.uncompressed_crc:
            msg = f"{self.path}: the chunk at byte {offset} is damaged (its CRC does not match)"
            raise RecordingError(msg)
        plain = Chunk(compression="", data=records, message_start_time=0, message_end_time=0,
                      uncompressed_size=len(records), uncompressed_crc=0)  # fmt: skip
        return breakup_chunk(plain)

    def _cut_chunk_records(self, start: int) -> bytes:
        """The records bytes that the beginning of a chunk cut by the file's end gives.

        A recorder killed while writing leaves such a chunk: the messages at its start are
        whole. Empty when the record at ``start`` is not a chunk or is not cut short (a
        chunk damaged inside the file is not trusted at all).
        """
        self.stream.seek(start)
        data = self.stream.read()
        if len(data) < _CHUNK_HEAD.size or data[0] != _CHUNK_OPCODE:
            return b""
        _, length, _, _, _, _, name_length = _CHUNK_HEAD.unpack_from(data)
        if _RECORD_HEAD.size + length <= len(data):  # whole: not cut by the file's end
            return b""
        name_end = _CHUNK_HEAD.size + name_length
        compression = data[_CHUNK_HEAD.size : name_end].decode("utf-8", "replace")
        return _readable_prefix(compression, data[name_end + _U64.size :])

    def messages(self, topics: set[str] | None) -> Iterator[RecordedMessage]:
        """The messages of ``topics`` (None: all), in log-time order."""
        if self.summary is None or not self.summary.chunk_indexes:
            yield from self._scan(topics)
            return
        for batch in self._chunk_batches(topics):
            yield from batch.messages()

    def batches(
        self, topics: set[str] | None, *, transient: bool = False
    ) -> Iterator[MessageBatch]:
        """``messages`` a chunk at a time (``transient``: see ``RecordingReader.batches``)."""
        if self.summary is None or not self.summary.chunk_indexes:
            return super().batches(topics)
        return self._chunk_batches(topics, transient=transient)

    def _chunk_batches(
        self, topics: set[str] | None, *, transient: bool = False
    ) -> Iterator[MessageBatch]:
        """The messages of ``topics``, a chunk at a time, in the ``mcap`` reader's order.

        That order is (log time, chunk offset, position in the chunk). Chunks are read by
        start time; the messages of the chunks read so far that come before the next chunk's
        start are complete and go out; the rest (chunks that overlap in time) wait for it.
        """
        summary = self.summary
        assert summary is not None
        table: dict[int, int] = {}
        names: list[str] = []
        types: list[str] = []
        for channel_id, channel in summary.channels.items():
            if topics is None or channel.topic in topics:
                schema = summary.schemas.get(channel.schema_id)
                table[channel_id] = len(names)
                names.append(channel.topic)
                types.append(normalize_msgtype(schema.name) if schema else "unknown/msg/Unknown")
        chunks = sorted(
            (
                c for c in summary.chunk_indexes
                if not c.message_index_offsets or any(i in table for i in c.message_index_offsets)
            ),
            key=lambda c: (c.message_start_time, c.chunk_start_offset),
        )  # fmt: skip
        waiting = _Located(b"", np.empty((0, _COLUMNS), dtype=np.int64))
        for k, chunk in enumerate(chunks):
            located = waiting.join(self._chunk_located(chunk, table, transient=transient))
            ready, waiting = located.split(
                (chunks[k + 1].message_start_time, chunks[k + 1].chunk_start_offset)
                if k + 1 < len(chunks) else None
            )  # fmt: skip
            if len(ready.rows):
                yield ready.batch(tuple(names), tuple(types))

    def _chunk_located(self, chunk: Any, table: dict[int, int], *, transient: bool) -> _Located:
        """The messages of one chunk (``ChunkIndex``); none when it is damaged.

        A damaged chunk (bytes changed, cut short) is skipped, not the rest of the file: its
        messages of the wanted channels are counted ``damaged_chunk`` in ``drops`` (as many as
        its message index lists) and the damage is described in ``problems``.
        """
        offset = chunk.chunk_start_offset
        try:
            records = self._chunk_records(offset, chunk.chunk_length, transient=transient)
            return self._locate(records, offset, table)
        except RecordingError as exc:
            lost = self._indexed_messages(chunk, table)
            reason = "oversized_chunk" if isinstance(exc, _OversizedChunkError) else "damaged_chunk"
            self.drops[reason] += lost if lost is not None else 1
            count = f"its {lost} messages" if lost is not None else "its messages"
            self.problems.append(f"{exc}; skipped {count}, read on after it")
            return _Located(b"", np.empty((0, _COLUMNS), dtype=np.int64))

    def _indexed_messages(self, chunk: Any, table: dict[int, int]) -> int | None:
        """Messages of the chunk on the channels of ``table``, from its message indexes."""
        count = 0
        try:
            for channel_id, index_offset in chunk.message_index_offsets.items():
                if channel_id in table:
                    self.stream.seek(index_offset)
                    head = self.stream.read(_MESSAGE_INDEX_HEAD.size)
                    opcode, _, _, entries_length = _MESSAGE_INDEX_HEAD.unpack(head)
                    if opcode != _MESSAGE_INDEX_OPCODE:
                        return None
                    count += entries_length // 16  # (log time, offset) per message
        except (OSError, ValueError, struct.error):
            return None
        return count if chunk.message_index_offsets else None

    def _chunk_records(
        self, offset: int, indexed_length: int, *, transient: bool = False
    ) -> bytes | memoryview:
        """The decompressed records of the chunk record at ``offset``, checked by their CRC.

        ``indexed_length``: the chunk record's length according to the summary, which is
        read (a damaged length field in the record itself is then harmless).
        ``transient``: zstd chunks are decompressed into one buffer kept for the next chunk,
        whose memory is mapped already: fresh 4 MB allocations cost more in page faults than
        the decompression itself.
        """
        self.stream.seek(offset)
        head = self.stream.read(_CHUNK_HEAD.size)
        if len(head) < _CHUNK_HEAD.size or head[0] != _CHUNK_OPCODE:
            msg = f"{self.path}: its index points at byte {offset}, where no chunk starts"
            raise RecordingError(msg)
        _, _, _, _, size, crc, name_length = _CHUNK_HEAD.unpack(head)
        if size > MAX_CHUNK_BYTES:
            raise _OversizedChunkError(self.path, offset, size)
        rest = self.stream.read(max(0, indexed_length - _CHUNK_HEAD.size))
        try:
            (data_length,) = _U64.unpack_from(rest, name_length)
        except struct.error:
            data_length = -1
        if name_length + 8 + data_length != len(rest):
            msg = f"{self.path}: the chunk at byte {offset} is damaged (its lengths disagree)"
            raise RecordingError(msg)
        compression = rest[:name_length].decode("utf-8", "replace")
        data = memoryview(rest)[name_length + 8 :]
        if transient and compression == "zstd":
            records: bytes | memoryview = self._decompress_into(data, size, offset)
        else:
            records = self._decompress(compression, data, size, offset)
        if crc and crc32(records) != crc:
            msg = f"{self.path}: the chunk at byte {offset} is damaged (its CRC does not match)"
            raise RecordingError(msg)
        return records

    def _decompress_into(self, data: memoryview, size: int, offset: int) -> memoryview:
        """A zstd chunk's records in the reused buffer (valid until the next chunk is read)."""
        import zstandard

        if len(self._scratch) < size:
            self._scratch = bytearray(size)
        view = memoryview(self._scratch)[:size]
        done = 0
        try:
            with zstandard.ZstdDecompressor().stream_reader(data) as stream:
                while done < size and (n := stream.readinto(view[done:])):
                    done += n
                extra = stream.read(1)
        except zstandard.ZstdError as exc:
            msg = f"{self.path}: cannot decompress the chunk at byte {offset}: {exc}"
            raise RecordingError(msg) from exc
        if done != size or extra:
            msg = f"{self.path}: the chunk at byte {offset} does not decompress to its {size} bytes"
            raise RecordingError(msg)
        return view

    def _locate(self, records: bytes, offset: int, table: dict[int, int]) -> _Located:
        """The messages in the records of the chunk at ``offset`` whose channel is in ``table``."""
        rows = []
        pos, end = 0, len(records)
        channels = self.summary.channels if self.summary is not None else {}
        while pos < end:
            if pos + 9 > end:
                break
            opcode, length = _RECORD_HEAD.unpack_from(records, pos)
            body = pos + 9
            pos = body + length
            if opcode != _MESSAGE_OPCODE or pos > end or length < _MESSAGE_HEAD.size:
                continue
            channel_id, _, log_time, _ = _MESSAGE_HEAD.unpack_from(records, body)
            index = table.get(channel_id)
            if index is not None and length - _MESSAGE_HEAD.size > MAX_MESSAGE_BYTES:
                self.drops["oversized_message"] += 1
            elif index is not None:
                rows.append((log_time, offset, body, index, body + _MESSAGE_HEAD.size, pos))
            elif channel_id not in channels:
                self.drops["unknown_channel"] += 1
        if pos != end:
            msg = f"{self.path}: the chunk at byte {offset} is damaged (a record runs past its end)"
            raise RecordingError(msg)
        return _Located(records, np.array(rows, dtype=np.int64).reshape(-1, _COLUMNS))

    def _decompress(self, compression: str, data: memoryview, size: int, offset: int) -> bytes:
        """A chunk's records, at most ``size`` bytes (the chunk's own uncompressed size).

        The decompressors are asked for ``size + 1`` bytes at most: a frame that claims, or
        inflates to, more than the chunk says (a 33 KB zstd frame of 1 GB) is refused
        without being inflated, whatever its own header says.
        """
        if size > MAX_CHUNK_BYTES:
            raise _OversizedChunkError(self.path, offset, size)
        try:
            if compression == "zstd":
                records = _zstd_prefix(data, size + 1)
            elif compression == "lz4":
                import lz4.frame

                records = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
            elif compression:
                msg = f"chunk compression {compression!r} is not supported (zstd or lz4)"
                raise RecordingError(f"{self.path}: {msg}")
            else:
                return bytes(data)
        except RecordingError:
            raise
        except Exception as exc:  # zstandard and lz4 raise their own error types
            msg = f"{self.path}: cannot decompress the chunk at byte {offset}: {exc}"
            raise RecordingError(msg) from exc
        if len(records) != size:
            msg = f"{self.path}: the chunk at byte {offset} does not decompress to its {size} bytes"
            raise RecordingError(msg)
        return records

    def close(self) -> None:
        """Close the file."""
        self.stream.close()


def _zstd_prefix(data: bytes | memoryview, limit: int) -> bytes:
    """The first ``limit`` bytes (or fewer: all) that zstd ``data`` decompresses to.

    ``zstandard.decompress`` allocates what the frame's header claims, whatever
    ``max_output_size`` says; a stream reader read up to ``limit`` never holds more.
    """
    import zstandard

    out = bytearray()
    with zstandard.ZstdDecompressor().stream_reader(data) as stream:
        while len(out) < limit and (piece := stream.read(min(1 << 20, limit - len(out)))):
            out += piece
    return bytes(out)


class _BoundedFile:
    """A binary file whose reads never ask for more bytes than the file still holds.

    A damaged length field (2^40, 2^63) passed to ``read`` made the buffered reader allocate
    that much at once (MemoryError) or fail to (OverflowError) before finding the file
    shorter; here such a read returns what is left, and the reader then meets the file's
    end as for any cut file. Everything else is the file's own.
    """

    def __init__(self, path: Path) -> None:
        self._file = path.open("rb")

    def read(self, size: int | None = -1) -> bytes:
        if size is None or size < 0:
            return self._file.read()
        left = os.fstat(self._file.fileno()).st_size - self._file.tell()
        return self._file.read(max(0, min(size, left)))

    def __getattr__(self, name: str) -> Any:
        return getattr(self._file, name)


def _readable_prefix(compression: str, data: bytes) -> bytes:
    """As much of a cut chunk's records as its compressed beginning ``data`` gives.

    zstd and lz4 frames decompress as a stream, so a cut frame still yields what came before
    the cut; a decompressor error ends the prefix where it happens.
    """
    if not compression:
        return data
    pieces: list[bytes] = []
    with contextlib.suppress(Exception):  # zstandard and lz4 raise their own error types
        if compression == "zstd":
            import zstandard

            reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data))
            read = 0
            while read < MAX_CHUNK_BYTES and (piece := reader.read(1 << 16)):
                pieces.append(piece)
                read += len(piece)
        elif compression == "lz4":
            import lz4.frame

            pieces.append(
                lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=MAX_CHUNK_BYTES)
            )
    return b"".join(pieces)


def _whole_records(records: bytes) -> list[Any]:
    """The complete records at the start of a chunk's records bytes (a cut one ends them)."""
    from mcap.records import Chunk
    from mcap.stream_reader import breakup_chunk

    end = 0
    while end + _RECORD_HEAD.size <= len(records):
        _, length = _RECORD_HEAD.unpack_from(records, end)
        if end + _RECORD_HEAD.size + length > len(records):
            break
        end += _RECORD_HEAD.size + length
    whole = Chunk(compression="", data=records[:end], message_start_time=0, message_end_time=0,
                  uncompressed_size=end, uncompressed_crc=0)  # fmt: skip
    return breakup_chunk(whole)


_CHUNK_OPCODE = 0x06
_MESSAGE_OPCODE = 0x05
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, record length
# chunk: opcode, length, message start/end time, uncompressed size, crc, compression length
_CHUNK_HEAD = struct.Struct("<BQQQQII")
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary start, offsets start, summary CRC
_MESSAGE_INDEX_OPCODE = 0x07
_MESSAGE_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, length, channel id, entries' length
_U64 = struct.Struct("<Q")
_COLUMNS = 6  # log time, chunk offset, record position, channel index, data start, data end


class _OversizedChunkError(RecordingError):
    """A chunk whose records would take more than ``MAX_CHUNK_BYTES``: not decompressed."""

    def __init__(self, path: Path, offset: int, size: int) -> None:
        super().__init__(
            f"{path}: the chunk at byte {offset} would decompress to {size} bytes, more than "
            f"the {MAX_CHUNK_BYTES} read (hiros_core.limits)"
        )


@dataclass(frozen=True)
class _Located:
    """Messages found in decompressed chunk records: the bytes and one row per message."""

    records: bytes
    rows: np.ndarray  # (n, _COLUMNS) int64

    def join(self, other: _Located) -> _Located:
        """Both sets of messages, with one buffer holding both."""
        if not len(self.rows):
            return other
        shifted = other.rows.copy()
        shifted[:, 4:] += len(self.records)
        return _Located(self.records + other.records, np.concatenate([self.rows, shifted]))

    def split(self, limit: tuple[int, int] | None) -> tuple[_Located, _Located]:
        """Sorted messages before ``limit`` (log time, chunk offset), and the others."""
        rows = self.rows[np.lexsort((self.rows[:, 2], self.rows[:, 1], self.rows[:, 0]))]
        if limit is None:
            return _Located(self.records, rows), _Located(b"", rows[:0])
        time, offset = limit
        ready = (rows[:, 0] < time) | ((rows[:, 0] == time) & (rows[:, 1] < offset))
        later = rows[~ready]
        kept = b"".join(self.records[a:b] for a, b in later[:, 4:].tolist())
        ends = np.cumsum(later[:, 5] - later[:, 4])
        later[:, 4], later[:, 5] = ends - (later[:, 5] - later[:, 4]), ends
        return _Located(self.records, rows[ready]), _Located(kept, later)

    def batch(self, topics: tuple[str, ...], msgtypes: tuple[str, ...]) -> MessageBatch:
        """The messages as a batch, in row order."""
        return MessageBatch(
            topics, msgtypes, self.rows[:, 3].astype(np.intp), self.rows[:, 0].copy(),
            self.records, self.rows[:, 4].copy(), self.rows[:, 5].copy(),
        )  # fmt: skip
