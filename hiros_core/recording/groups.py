"""Skeleton streams of a recording: SkeletonGroup topics and Azure-driver MarkerArray topics.

The one place where recorded bytes become the model offline: SkeletonGroup messages are
decoded by the codec, driver MarkerArrays by the codec and then a ``DriverBridge`` per topic,
exactly what the bridge node does live, so offline and live runs see the same groups.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path

from hiros_core.codec import decode_group
from hiros_core.errors import CodecError
from hiros_core.model import SkeletonGroup
from hiros_core.recording.reader import RecordingReader
from hiros_core.recording.writer import MARKER_ARRAY, SKELETON_GROUP

__all__ = ["DRIVER_TOPIC_SUFFIX", "group_topics", "iter_groups", "source_name"]

DRIVER_TOPIC_SUFFIX = "body_tracking_data"
"""Last name of the Azure Kinect driver's skeleton topic (``/<cam>/body_tracking_data``)."""
_CAMERA_TOPICS = (DRIVER_TOPIC_SUFFIX, "skeletons")


def source_name(topic: str) -> str:
    """``/k01/body_tracking_data`` and ``/k01/skeletons`` -> ``k01``; other topics unchanged."""
    parts = topic.strip("/").split("/")
    if len(parts) == 2 and parts[1] in _CAMERA_TOPICS:
        return parts[0]
    return topic


def group_topics(topics: dict[str, str]) -> dict[str, str]:
    """The topics ``iter_groups`` reads by default: ``{topic: msgtype}``.

    Every SkeletonGroup topic, and MarkerArray topics named ``.../body_tracking_data`` (other
    MarkerArrays, such as the visualiser's, are drawings, not detections).
    """
    return {
        topic: msgtype
        for topic, msgtype in topics.items()
        if msgtype == SKELETON_GROUP
        or (msgtype == MARKER_ARRAY and topic.rstrip("/").endswith(DRIVER_TOPIC_SUFFIX))
    }


def iter_groups(
    recording: str | Path | RecordingReader,
    *,
    topics: Iterable[str] | None = None,
    bridge_params: object | None = None,
    drops: Counter[str] | None = None,
) -> Iterator[tuple[str, SkeletonGroup]]:
    """``(source, group)`` for every skeleton message, in log-time order.

    Args:
        recording: a path (opened and closed here) or an open ``RecordingReader``.
        topics: topics to read; default ``group_topics`` of the recording. A MarkerArray
            topic given here is read as driver output whatever its name.
        bridge_params: ``DriverBridgeParams`` for MarkerArray topics (default: Azure driver).
        drops: counter that receives, when the iteration ends, the reader's and bridges'
            drop reasons plus ``undecodable`` (bytes the codec rejects).

    Yields:
        ``source`` is the camera name for ``/<cam>/body_tracking_data`` and
        ``/<cam>/skeletons``, else the topic; ``group`` is in the message's frame and clock.

    """
    from hiros_azure_bridge.driver_format import DriverBridge

    reader = recording if isinstance(recording, RecordingReader) else RecordingReader(recording)
    drops = drops if drops is not None else Counter()
    wanted = (
        group_topics(reader.topics)
        if topics is None
        else {t: reader.topics[t] for t in topics if t in reader.topics}
    )
    bridges: dict[str, DriverBridge] = {}
    try:
        for message in reader.messages(wanted):
            source = source_name(message.topic)
            try:
                if message.msgtype == SKELETON_GROUP:
                    yield source, decode_group(message.data)
                    continue
                if message.msgtype != MARKER_ARRAY:
                    drops["not_skeletons"] += 1
                    continue
                bridge = bridges.get(message.topic)
                if bridge is None:
                    bridge = bridges[message.topic] = DriverBridge(bridge_params)
                group = bridge.update_bytes(message.data)
            except CodecError:
                drops["undecodable"] += 1
                continue
            if group is not None:
                yield source, group
    finally:
        for counter in (reader.drops, *(b.drops for b in bridges.values())):
            drops.update({reason: n for reason, n in counter.items() if n})
        if reader is not recording:
            reader.close()
