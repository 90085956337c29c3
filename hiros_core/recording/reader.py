"""Read recordings: rosbag2 folders, single ``.mcap`` / ``.db3`` files and ROS 1 ``.bag`` files.

``RecordingReader`` streams every message as raw CDR bytes with its topic, type and log time,
in log-time order across topics and files, holding only a few chunks in memory at once:

* MCAP (single file or a rosbag2 folder's files) is read through its chunk index: each chunk
  is read and decompressed once and its message records located without a Python object per
  message, in the order the ``mcap`` library's reader gives (log time, then chunk position,
  then position in the chunk). A file without a valid summary (the recorder was killed) is
  read straight through by the ``mcap`` library, in file order, up to its last complete
  record, and then the whole messages at the start of a chunk the file's end cuts (zstd and
  lz4 decompress as a stream); what could not be read is counted ``truncated`` in ``drops``
  and described in ``problems``. Each chunk is checked against its CRC; a damaged chunk is
  skipped (its messages counted ``damaged_chunk``) and reading goes on after it. A summary
  that fails its CRC is not trusted: the file is then read straight through.
* sqlite3 (``.db3``) and ROS 1 bags are read with ``rosbags``' ``AnyReader``. ROS 1 messages
  are converted to ROS 2 CDR of the ROS 2 Jazzy type of the same name (a ROS 1 header's
  ``seq`` goes, newer fields get defaults), so every consumer sees one wire format.

``RecordingReader.batches`` gives the same messages as ``MessageBatch``es (one MCAP chunk's
messages in one buffer), for consumers that decode many messages per call.
"""

from __future__ import annotations

import heapq
from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path
from types import TracebackType

from hiros_core.errors import RecordingError
from hiros_core.outputs import BAG_METADATA
from hiros_core.recording.mcap_source import McapSource
from hiros_core.recording.messages import MessageBatch, RecordedMessage, Source, batched
from hiros_core.recording.rosbags_source import REINDEX, RosbagsSource
from hiros_core.safe_yaml import load_yaml

__all__ = ["UNCOUNTED_DROPS", "MessageBatch", "RecordedMessage", "RecordingReader"]


UNCOUNTED_DROPS = frozenset({"truncated"})
"""Reasons in ``RecordingReader.drops`` counted once per occurrence, not per message: how
many messages a file's cut end took is unknown. The others count messages."""

_MAX_METADATA_BYTES = 8 << 20
"""Largest rosbag2 ``metadata.yaml`` read (one of a thousand topics and files is ~1 MB)."""


def _folder_sources(path: Path, drops: Counter[str], problems: list[str]) -> list[Source]:
    """The sources of a rosbag2 folder, with or without its ``metadata.yaml``."""
    metadata = path / BAG_METADATA
    files: list[Path] = []
    storage = ""
    if metadata.is_file():
        document = load_yaml(
            metadata, what="rosbag2 metadata", error=RecordingError, max_bytes=_MAX_METADATA_BYTES
        )
        try:
            info = document["rosbag2_bagfile_information"]
            storage = str(info.get("storage_identifier", ""))
            files = [path / Path(p).name for p in info.get("relative_file_paths", [])]
            compressed = str(info.get("compression_mode", "") or "").lower() not in {"", "none"}
        except (KeyError, TypeError, AttributeError) as exc:
            msg = f"cannot read {metadata}: no rosbag2_bagfile_information ({exc!r})"
            raise RecordingError(msg) from exc
        if compressed or storage not in {"mcap", "sqlite3"}:
            return [RosbagsSource(path)]
        if storage == "sqlite3":
            return [RosbagsSource(path)]
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
        McapSource(f, drops, problems) if f.suffix == ".mcap" else RosbagsSource(f) for f in files
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
            self._sources = [McapSource(self.path, self.drops, self.problems)]
        elif self.path.suffix in {".db3", ".bag"}:
            self._sources = [RosbagsSource(self.path)]
        elif self.path.name.endswith(".bag.active"):
            msg = f"cannot read {self.path}: {REINDEX}"
            raise RecordingError(msg)
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

    def batches(
        self, topics: Iterable[str] | None = None, *, transient: bool = False
    ) -> Iterator[MessageBatch]:
        """``messages(topics)`` as ``MessageBatch``es, same messages in the same order.

        A recording of one indexed MCAP file comes a chunk at a time without per-message
        objects; any other recording comes ``messages`` grouped a few hundred at a time.
        ``transient``: a batch's ``buffer`` may be reused for the next batch's bytes (for a
        consumer done with each batch before it asks for the next, such as ``iter_groups``),
        which saves mapping fresh memory for every chunk.
        """
        wanted = set(topics) if topics is not None else None
        if len(self._sources) == 1:
            return self._sources[0].batches(wanted, transient=transient)
        return batched(self.messages(wanted))

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
