"""Read recordings: rosbag2 folders, single ``.mcap`` / ``.db3`` files and ROS 1 ``.bag`` files.

``RecordingReader`` streams every message as raw CDR bytes with its topic, type and log time,
in log-time order across topics and files, holding only a few chunks in memory at once:

* MCAP (single file or a rosbag2 folder's files) is read with the ``mcap`` library through its
  chunk index. A file without a valid summary (the recorder was killed) is read straight
  through, in file order, up to its last complete record; what could not be read is counted
  ``truncated`` in ``drops`` and described in ``problems``.
* sqlite3 (``.db3``) and ROS 1 bags are read with ``rosbags``' ``AnyReader``. ROS 1 messages
  are converted to ROS 2 CDR of the ROS 2 Jazzy type of the same name (a ROS 1 header's
  ``seq`` goes, newer fields get defaults), so every consumer sees one wire format.
"""

from __future__ import annotations

import contextlib
import heapq
import io
import struct
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import yaml

from hiros_core.errors import RecordingError
from hiros_core.recording.msgdefs import normalize_msgtype

__all__ = ["RecordedMessage", "RecordingReader"]


@dataclass(frozen=True)
class RecordedMessage:
    """One message of a recording.

    Attributes:
        topic: topic name (``/k01/body_tracking_data``).
        msgtype: ``package/msg/Type``.
        log_time_ns: when the recorder received it (integer ns); the order of reading.
        data: ROS 2 CDR bytes, encapsulation header included.

    """

    topic: str
    msgtype: str
    log_time_ns: int
    data: bytes


class _Source:
    """One readable file or folder: topics up front, then a time-ordered message stream."""

    topics: dict[str, str]

    def messages(self, topics: set[str] | None) -> Iterator[RecordedMessage]:
        raise NotImplementedError

    def close(self) -> None:
        """Release open files."""


class _McapSource(_Source):
    """A single MCAP file, read through its index, or straight through when truncated."""

    def __init__(self, path: Path, drops: Counter[str], problems: list[str]) -> None:
        from mcap.exceptions import McapError
        from mcap.reader import SeekingReader

        self.path = path
        self.drops = drops
        self.problems = problems
        try:
            self.stream = path.open("rb")
        except OSError as exc:
            msg = f"cannot open recording {path}: {exc}"
            raise RecordingError(msg) from exc
        self.summary = None
        try:
            self.reader = SeekingReader(self.stream)
            self.summary = self.reader.get_summary()
        except (McapError, ValueError, struct.error, OSError) as exc:
            if self.stream.seek(0, io.SEEK_END) < 8:
                self.stream.close()
                msg = f"{path} is not an MCAP file (too short: {exc})"
                raise RecordingError(msg) from None
            self.stream.seek(0)
            if self.stream.read(8) != b"\x89MCAP0\r\n":
                self.stream.close()
                msg = f"{path} is not an MCAP file (no MCAP magic bytes at its start)"
                raise RecordingError(msg) from None
        if self.summary is not None and self.summary.chunk_indexes:
            self.topics = {
                c.topic: normalize_msgtype(self.summary.schemas[c.schema_id].name)
                for c in self.summary.channels.values()
                if c.schema_id in self.summary.schemas
            }
        else:
            self.topics = {}
            for _ in self._scan(None, collect_only=True):
                pass

    def _scan(self, topics: set[str] | None, *, collect_only: bool = False) -> Iterator[Any]:
        """Records straight through the file, stopping cleanly at the first unreadable byte."""
        from mcap.exceptions import McapError
        from mcap.records import Channel, Footer, Message, Schema
        from mcap.stream_reader import StreamReader

        self.stream.seek(0)
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        count = 0
        records = StreamReader(self.stream, skip_magic=False).records
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
                    elif topics is None or topic in topics:
                        count += 1
                        yield RecordedMessage(topic, msgtype, record.log_time, record.data)
                elif isinstance(record, Footer):
                    return
        except (McapError, ValueError, struct.error, EOFError, OSError) as exc:
            if not collect_only:
                self.drops["truncated"] += 1
                self.problems.append(
                    f"{self.path} ends early or is damaged at byte {self.stream.tell()} "
                    f"({type(exc).__name__}: {exc}); read {count} messages before that "
                    "(a recorder that was stopped without closing the file leaves this)"
                )

    def messages(self, topics: set[str] | None) -> Iterator[RecordedMessage]:
        if self.summary is None or not self.summary.chunk_indexes:
            yield from self._scan(topics)
            return
        wanted = list(topics) if topics is not None else None
        for schema, channel, message in self.reader.iter_messages(topics=wanted):
            msgtype = normalize_msgtype(schema.name) if schema else "unknown/msg/Unknown"
            yield RecordedMessage(channel.topic, msgtype, message.log_time, message.data)

    def close(self) -> None:
        self.stream.close()


class _RosbagsSource(_Source):
    """A ``.db3`` file, a sqlite3 rosbag2 folder, or a ROS 1 bag, through ``AnyReader``."""

    def __init__(self, path: Path) -> None:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore

        self.path = path
        self.reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY))
        try:
            self.reader.open()
        except (AnyReaderError, OSError, ValueError, KeyError) as exc:
            msg = f"cannot read recording {path}: {exc}"
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
        with contextlib.suppress(Exception):
            self.reader.close()


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


def _folder_sources(path: Path, drops: Counter[str], problems: list[str]) -> list[_Source]:
    """The sources of a rosbag2 folder, with or without its ``metadata.yaml``."""
    metadata = path / "metadata.yaml"
    files: list[Path] = []
    storage = ""
    if metadata.is_file():
        try:
            info = yaml.safe_load(metadata.read_text())["rosbag2_bagfile_information"]
            storage = str(info.get("storage_identifier", ""))
            files = [path / Path(p).name for p in info.get("relative_file_paths", [])]
            compressed = str(info.get("compression_mode", "") or "").lower() not in {"", "none"}
        except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError) as exc:
            msg = f"cannot read {metadata}: {exc}"
            raise RecordingError(msg) from exc
        if compressed or storage not in {"mcap", "sqlite3"}:
            return [_RosbagsSource(path)]
        if storage == "sqlite3":
            return [_RosbagsSource(path)]
        missing = [f.name for f in files if not f.is_file()]
        if missing:
            problems.append(f"{path}: files listed in metadata.yaml are missing: {missing}")
            drops["missing_file"] += len(missing)
            files = [f for f in files if f.is_file()]
    else:
        files = sorted(path.glob("*.mcap")) or sorted(path.glob("*.db3"))
        if files:
            problems.append(f"{path} has no metadata.yaml; reading its {len(files)} file(s)")
    if not files:
        msg = f"{path} holds no recording (no metadata.yaml, .mcap or .db3 files)"
        raise RecordingError(msg)
    return [
        _McapSource(f, drops, problems) if f.suffix == ".mcap" else _RosbagsSource(f) for f in files
    ]


class RecordingReader:
    """Messages of a recording, as raw CDR, in log-time order.

    Args:
        path: a rosbag2 folder, a ``.mcap`` or ``.db3`` file, or a ROS 1 ``.bag`` file.

    Attributes:
        path: the recording.
        topics: ``{topic: msgtype}`` of every topic (types as ``package/msg/Type``).
        drops: what could not be read, by reason (``truncated``, ``missing_file``, ...).
        problems: one sentence per problem met, for the user.

    Raises:
        RecordingError: the path does not exist or is no recording we can read.

    Use as a context manager, or call ``close()``::

        with RecordingReader("take.mcap") as recording:
            for message in recording.messages({"/k01/body_tracking_data"}):
                ...

    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.drops: Counter[str] = Counter()
        self.problems: list[str] = []
        if not self.path.exists():
            msg = f"recording {self.path} does not exist"
            raise RecordingError(msg)
        if self.path.is_dir():
            self._sources = _folder_sources(self.path, self.drops, self.problems)
        elif self.path.suffix == ".mcap":
            self._sources = [_McapSource(self.path, self.drops, self.problems)]
        elif self.path.suffix in {".db3", ".bag"}:
            self._sources = [_RosbagsSource(self.path)]
        else:
            msg = (
                f"{self.path} is not a recording: expected a rosbag2 folder or a .mcap, .db3 "
                "or .bag file"
            )
            raise RecordingError(msg)
        self.topics: dict[str, str] = {}
        for source in self._sources:
            self.topics.update(source.topics)

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[RecordedMessage]:
        """Every message (or those of ``topics``) in log-time order across topics and files."""
        wanted = set(topics) if topics is not None else None
        streams = [source.messages(wanted) for source in self._sources]
        if len(streams) == 1:
            yield from streams[0]
        else:
            yield from heapq.merge(*streams, key=lambda m: m.log_time_ns)

    def __iter__(self) -> Iterator[RecordedMessage]:
        return self.messages()

    def close(self) -> None:
        """Close every file of the recording."""
        for source in self._sources:
            source.close()

    def __enter__(self) -> RecordingReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()
