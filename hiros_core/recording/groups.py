"""Skeleton streams of a recording: SkeletonGroup topics and Azure-driver MarkerArray topics.

The one place where recorded bytes become the model offline: SkeletonGroup messages are
decoded by the codec, driver MarkerArrays by a ``DriverBridge`` per topic, exactly what the
bridge node does live, so offline and live runs see the same groups. Messages are read a batch
(an MCAP chunk) at a time, and each topic's driver messages of a batch go to its bridge
together (``DriverBridge.update_batch``): bridges of different topics share no state, so this
gives the groups of a message-by-message reading, in the same order.
"""

from __future__ import annotations

import contextlib
from collections import Counter, defaultdict
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from hiros_core.accounting import Drops
from hiros_core.codec import decode_group
from hiros_core.driver import DriverBridge, DriverBridgeParams
from hiros_core.errors import CodecError, RecordingError
from hiros_core.model import SkeletonGroup
from hiros_core.recording.reader import UNCOUNTED_DROPS, MessageBatch, RecordingReader
from hiros_core.recording.writer import MARKER_ARRAY, SKELETON_GROUP

__all__ = [
    "DRIVER_TOPIC_SUFFIX",
    "group_topics",
    "iter_groups",
    "iter_logged_groups",
    "read_camera_groups",
    "require_camera_topics",
    "source_name",
]

DRIVER_TOPIC_SUFFIX = "body_tracking_data"
"""Last name of the Azure Kinect driver's skeleton topic (``/<cam>/body_tracking_data``)."""
_CAMERA_TOPICS = (DRIVER_TOPIC_SUFFIX, "skeletons")
PIPELINE_OUTPUTS = frozenset(f"/hiros/{s}" for s in ("tracker", "merger", "optimizer", "filter"))
"""The pipeline's own SkeletonGroup outputs: people already fused, not any camera's frames."""


def source_name(topic: str) -> str:
    """``/k01/body_tracking_data`` and ``/k01/skeletons`` -> ``k01``; other topics unchanged."""
    parts = topic.strip("/").split("/")
    if len(parts) == 2 and parts[1] in _CAMERA_TOPICS:
        return parts[0]
    return topic


def group_topics(topics: dict[str, str]) -> dict[str, str]:
    """The topics ``iter_groups`` reads by default: ``{topic: msgtype}``.

    Every SkeletonGroup topic but the pipeline's outputs (``PIPELINE_OUTPUTS``, found in a
    recording of a live session or a ``hiros run`` output), and MarkerArray topics named
    ``.../body_tracking_data`` (other MarkerArrays, such as the visualiser's, are drawings,
    not detections).
    """
    return {
        topic: msgtype
        for topic, msgtype in topics.items()
        if (msgtype == SKELETON_GROUP and topic not in PIPELINE_OUTPUTS)
        or (msgtype == MARKER_ARRAY and topic.rstrip("/").endswith(DRIVER_TOPIC_SUFFIX))
    }


def iter_groups(
    recording: str | Path | RecordingReader,
    *,
    topics: Iterable[str] | None = None,
    bridge_params: DriverBridgeParams | None = None,
    drops: Counter[str] | None = None,
    problems: list[str] | None = None,
) -> Iterator[tuple[str, SkeletonGroup]]:
    """``(source, group)`` for every skeleton message, in log-time order.

    Args:
        recording: a path (opened and closed here) or an open ``RecordingReader``.
        topics: topics to read; default ``group_topics`` of the recording. A MarkerArray
            topic given here is read as driver output whatever its name.
        bridge_params: ``DriverBridgeParams`` for MarkerArray topics (default: Azure driver).
        drops: counter that receives, when the iteration ends, the reader's and bridges'
            drop reasons plus ``undecodable`` (bytes the codec rejects); a ``Drops`` also
            learns which reasons dropped whole messages (all of the reader's do). A file's
            cut end is not among them (the messages it took are unknown): ``problems``
            tells it.
        problems: list that receives, when the iteration ends, the reader's sentences on
            what it met (a truncated file, a damaged chunk), for the user.

    Yields:
        ``source`` is the camera name for ``/<cam>/body_tracking_data`` and
        ``/<cam>/skeletons``, else the topic; ``group`` is in the message's frame and clock.

    """
    logged = iter_logged_groups(
        recording, topics=topics, bridge_params=bridge_params, drops=drops, problems=problems
    )
    with contextlib.closing(logged):
        for source, group, _ in logged:
            yield source, group


def iter_logged_groups(
    recording: str | Path | RecordingReader,
    *,
    topics: Iterable[str] | None = None,
    bridge_params: DriverBridgeParams | None = None,
    drops: Counter[str] | None = None,
    problems: list[str] | None = None,
) -> Iterator[tuple[str, SkeletonGroup, int]]:
    """``iter_groups`` with each group's log time (when the recorder received it), in ns."""
    reader = recording if isinstance(recording, RecordingReader) else RecordingReader(recording)
    lost = Drops()
    wanted = (
        group_topics(reader.topics)
        if topics is None
        else {t: reader.topics[t] for t in topics if t in reader.topics}
    )
    bridges: dict[str, DriverBridge] = {}
    batches = reader.batches(wanted, transient=True)  # each batch is read before the next
    try:
        for batch in _first_split(batches):
            groups = _batch_groups(batch, bridges, bridge_params, lost)
            sources = [source_name(topic) for topic in batch.topics]
            found = zip(batch.channels.tolist(), batch.log_times_ns.tolist(), groups, strict=True)
            for channel, log_time, group in found:
                if group is not None:
                    yield sources[channel], group, log_time
    finally:
        lost.add(_counted(reader.drops), frames=True)  # messages (a cut end: in ``problems``)
        for bridge in bridges.values():
            lost.add(bridge.drops)
        if isinstance(drops, Drops):
            drops.add(lost)
        elif drops is not None:
            drops.update(lost)
        if problems is not None:
            problems.extend(reader.problems)
        if reader is not recording:
            reader.close()


def read_camera_groups(
    recording: str | Path | RecordingReader,
    drops: Counter[str] | None = None,
    problems: list[str] | None = None,
) -> tuple[dict[str, list[SkeletonGroup]], dict[str, list[int]]]:
    """Per camera its SkeletonGroups and the log (arrival) time of each, ns, in log order.

    What a calibration reads (``iter_logged_groups`` gathered by source); ``drops`` and
    ``problems`` receive the reader's (see ``iter_groups``).
    """
    groups: dict[str, list[SkeletonGroup]] = defaultdict(list)
    arrivals: dict[str, list[int]] = defaultdict(list)
    logged = iter_logged_groups(recording, drops=drops, problems=problems)
    with contextlib.closing(logged):
        for source, group, log_time in logged:
            groups[source].append(group)
            arrivals[source].append(log_time)
    return dict(groups), dict(arrivals)


def require_camera_topics(recording: str | Path) -> None:
    """Refuse, before any work or output, a recording that holds no camera skeleton topic.

    Raises:
        RecordingError: naming the topics the recording does hold.

    """
    with RecordingReader(recording) as reader:
        topics = reader.topics
    if not group_topics(topics):
        msg = (
            f"{recording} holds no camera skeletons (SkeletonGroup topics or Azure-driver "
            f"MarkerArray topics /<camera>/body_tracking_data); its topics: {sorted(topics)}"
        )
        raise RecordingError(msg)


_FIRST_MESSAGES = 8
"""Messages of the first piece of the first batch; the next pieces double in size."""


def _first_split(batches: Iterable[MessageBatch]) -> Iterator[MessageBatch]:
    """``batches``, the first one in pieces of 8, 16, 32... messages.

    The first groups then come out after a few messages instead of a whole chunk's (~200,
    10-20 ms to decode), and each piece is decoded while the consumer handles the previous
    one's groups: ``hiros run``'s second process starts that much sooner.
    """
    iterator = iter(batches)
    rest = next(iterator, None)
    size = _FIRST_MESSAGES
    while rest is not None and len(rest) > size:
        piece, rest = rest.split(size)
        yield piece
        size *= 2
    if rest is not None:
        yield rest
    yield from iterator


def _batch_groups(
    batch: MessageBatch,
    bridges: dict[str, DriverBridge],
    bridge_params: DriverBridgeParams | None,
    drops: Drops,
) -> list[SkeletonGroup | None]:
    """The group of each message of ``batch`` (None: dropped, the reason counted)."""
    groups: list[SkeletonGroup | None] = [None] * len(batch)
    for channel, (topic, msgtype) in enumerate(zip(batch.topics, batch.msgtypes, strict=True)):
        rows = np.flatnonzero(batch.channels == channel)
        if msgtype == SKELETON_GROUP:
            for i in rows.tolist():
                try:
                    groups[i] = decode_group(batch.data(i))
                except CodecError as exc:  # OverLimitError: too_many_bodies
                    drops.frame(getattr(exc, "reason", "undecodable"))
        elif msgtype == MARKER_ARRAY:
            bridge = bridges.get(topic)
            if bridge is None:
                bridge = bridges[topic] = DriverBridge(bridge_params)
            made = bridge.update_batch(batch.buffer, batch.starts[rows], batch.ends[rows])
            for i, group in zip(rows.tolist(), made, strict=True):
                groups[i] = group
        else:
            drops.frame("not_skeletons", len(rows))
    return groups


def _counted(drops: Counter[str]) -> Counter[str]:
    """The reader's drops that count messages (see ``UNCOUNTED_DROPS``)."""
    return Counter({reason: n for reason, n in drops.items() if reason not in UNCOUNTED_DROPS})
