"""What a recording's sources give: ``RecordedMessage``, ``MessageBatch`` and the source base.

A source (``mcap_source``, ``rosbags_source``) streams one file's messages in log-time order;
``RecordingReader`` merges its files' sources.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

_BATCH_SIZE = 256
"""Messages per batch of a recording read one message at a time (not an indexed MCAP)."""


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


@dataclass(frozen=True, eq=False)
class MessageBatch:
    """Consecutive messages of a recording, in log-time order, whose bytes share one buffer.

    An MCAP chunk's messages come as one batch without a Python object per message, so a
    consumer can decode many of them per call (``iter_groups`` does).

    Attributes:
        topics: topic of each channel index.
        msgtypes: ``package/msg/Type`` of each channel index.
        channels: ``(n,)`` channel index of each message.
        log_times_ns: ``(n,)`` int64 log times.
        buffer: the bytes holding every message's data (a memoryview for ``transient``
            batches, whose bytes are replaced by the next batch's).
        starts: ``(n,)`` int64 where each message's CDR bytes start in ``buffer``.
        ends: ``(n,)`` int64 where they end.

    """

    topics: tuple[str, ...]
    msgtypes: tuple[str, ...]
    channels: np.ndarray
    log_times_ns: np.ndarray
    buffer: bytes | memoryview
    starts: np.ndarray
    ends: np.ndarray

    def __len__(self) -> int:
        return len(self.channels)

    def data(self, index: int) -> bytes:
        """The CDR bytes of message ``index`` (a copy)."""
        return bytes(self.buffer[self.starts[index] : self.ends[index]])

    def split(self, at: int) -> tuple[MessageBatch, MessageBatch]:
        """The first ``at`` messages and the rest, as two batches sharing this one's buffer."""
        return self._rows(slice(None, at)), self._rows(slice(at, None))

    def _rows(self, rows: slice) -> MessageBatch:
        return MessageBatch(
            self.topics, self.msgtypes, self.channels[rows], self.log_times_ns[rows],
            self.buffer, self.starts[rows], self.ends[rows],
        )  # fmt: skip

    def messages(self) -> Iterator[RecordedMessage]:
        """The batch as ``RecordedMessage``s."""
        topics, msgtypes, buffer = self.topics, self.msgtypes, self.buffer
        rows = zip(
            self.channels.tolist(), self.log_times_ns.tolist(), self.starts.tolist(),
            self.ends.tolist(), strict=True,
        )  # fmt: skip
        for channel, log_time, start, end in rows:
            yield RecordedMessage(
                topics[channel], msgtypes[channel], log_time, bytes(buffer[start:end])
            )

    @classmethod
    def of(cls, messages: Sequence[RecordedMessage]) -> MessageBatch:
        """A batch of ``messages`` (their bytes copied into one buffer)."""
        table: dict[tuple[str, str], int] = {}
        channels = [table.setdefault((m.topic, m.msgtype), len(table)) for m in messages]
        ends = np.cumsum([len(m.data) for m in messages], dtype=np.int64)
        return cls(
            topics=tuple(topic for topic, _ in table),
            msgtypes=tuple(msgtype for _, msgtype in table),
            channels=np.array(channels, dtype=np.intp),
            log_times_ns=np.array([m.log_time_ns for m in messages], dtype=np.int64),
            buffer=b"".join(m.data for m in messages),
            starts=ends - [len(m.data) for m in messages],
            ends=ends,
        )


def batched(messages: Iterable[RecordedMessage]) -> Iterator[MessageBatch]:
    """Messages read one at a time, as batches of up to ``_BATCH_SIZE``."""
    batch: list[RecordedMessage] = []
    for message in messages:
        batch.append(message)
        if len(batch) == _BATCH_SIZE:
            yield MessageBatch.of(batch)
            batch = []
    if batch:
        yield MessageBatch.of(batch)


class Source:
    """One readable file or folder: topics up front, then a time-ordered message stream."""

    topics: dict[str, str]

    def messages(self, topics: set[str] | None) -> Iterator[RecordedMessage]:
        """The messages of ``topics`` (None: all), in log-time order."""
        raise NotImplementedError

    def batches(
        self, topics: set[str] | None, *, transient: bool = False
    ) -> Iterator[MessageBatch]:
        """``messages`` as batches (``transient``: see ``RecordingReader.batches``)."""
        return batched(self.messages(topics))

    def close(self) -> None:
        """Release open files."""
