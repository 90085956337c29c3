"""Write recordings as MCAP, the ``ros2 bag`` default storage, laid out as rosbag2 Jazzy writes it.

Messages go in as raw CDR bytes, so anything the codec or rclpy serialises can be recorded
without building message objects. Each type's schema is its complete ``ros2msg`` definition
(``msgdefs``), which is what ``ros2 bag`` and Foxglove need to decode a topic they have no
installed package for. As rosbag2's MCAP storage plugin (``rosbag2_storage_mcap``) does, every
channel carries ``offered_qos_profiles`` (the QoS a live hiros node offers on that topic, in
rosbag2's YAML) and ``topic_type_hash`` (REP-2011), and the file ends its data with a
``rosbag2`` metadata record holding the bag's metadata (``serialized_metadata``, version 9).

A path ending in ``.mcap`` gives a single file; any other path gives a rosbag2 folder holding
``<name>_0.mcap`` and the ``metadata.yaml`` that ``ros2 bag info``/``play`` read.
"""

from __future__ import annotations

import contextlib
from collections import Counter
from pathlib import Path
from types import TracebackType
from typing import IO

import numpy as np
import yaml

from hiros_core.errors import RecordingError
from hiros_core.outputs import BAG_METADATA
from hiros_core.recording.mcap_out import COMPRESSIONS, ZSTD_LEVEL, McapWriter
from hiros_core.recording.msgdefs import message_definition, normalize_msgtype, type_hash

__all__ = [
    "MARKER_ARRAY",
    "SKELETON_GROUP",
    "RecordingWriter",
]

SKELETON_GROUP = "hiros_skeleton_msgs/msg/SkeletonGroup"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"

_INFINITE = {"sec": 9223372036, "nsec": 854775807}  # RMW_DURATION_INFINITE, as rosbag2 records it


def _offered_qos(depth: int, durability: str) -> list[dict[str, object]]:
    """One publisher's offered QoS in rosbag2's metadata version 9 form (policy names)."""
    return [
        {
            "history": "keep_last",
            "depth": depth,
            "reliability": "reliable",
            "durability": durability,
            "deadline": dict(_INFINITE),
            "lifespan": dict(_INFINITE),
            "liveliness": "automatic",
            "liveliness_lease_duration": dict(_INFINITE),
            "avoid_ros_namespace_conventions": False,
        }
    ]


# What hiros nodes offer: reliable, keep last 10 (``hiros_ros.node.pipeline_qos``); latched
# topics (a static transform broadcaster's, the calibration published once) keep their last
# message for late subscribers, so that ``ros2 bag play`` republishes them that way.
_STREAM_QOS = _offered_qos(10, "volatile")
_LATCHED_QOS = _offered_qos(1, "transient_local")
_LATCHED_TOPICS = frozenset({"/tf_static", "/hiros/calibration"})


def offered_qos(topic: str) -> list[dict[str, object]]:
    """The QoS profiles recorded as offered on ``topic``."""
    return _LATCHED_QOS if topic in _LATCHED_TOPICS else _STREAM_QOS


class _Route:
    """Where messages of a (topic, type spelling) go.

    Their channel, the channel's message count (the MCAP sequence) and the (topic, normalised
    type) they are counted under; spellings of one type share one route.
    """

    __slots__ = ("channel", "counted", "sequence")

    def __init__(self, channel: int, counted: tuple[str, str]) -> None:
        self.channel = channel
        self.counted = counted
        self.sequence = 0


_MAX_TIME_NS = (1 << 64) - 1


def _checked_time(topic: str, time_ns: int) -> int:
    """``time_ns`` as an int, refused when MCAP cannot store it (unsigned 64-bit ns).

    Checked before anything is written: a bad time met inside the MCAP writer would leave its
    chunk half-recorded, and the file could not be finished.
    """
    time_ns = int(time_ns)
    if not 0 <= time_ns <= _MAX_TIME_NS:
        msg = f"{topic}: time {time_ns} ns cannot be recorded (MCAP times are 0 to 2^64-1 ns)"
        raise RecordingError(msg)
    return time_ns


class RecordingWriter:
    """Append messages to a new MCAP recording.

    Args:
        path: ``*.mcap`` for one file, anything else for a rosbag2 folder (created).
        compression: ``zstd`` (default, at a fast level), ``lz4`` or ``none`` for the MCAP
            chunks; chunks are compressed and written by a helper thread (``mcap_out``).
        chunk_size: bytes per chunk before compression; a reader holds about one chunk per
            topic in memory.
        level: zstd level (default ``mcap_out.ZSTD_LEVEL``; negative is faster and larger).
        discard_on_error: as a context manager, delete the recording (:meth:`discard`) when
            the block or the closing fails with an error, so that a failed run or conversion
            leaves no half-written output to pass for one; an interrupt (Ctrl-C) keeps it.
        bag_metadata: for one ``.mcap`` file, also write rosbag2's ``metadata.yaml`` beside
            it, so that its folder opens as a bag (``hiros simulate``'s folder, where the
            recording lies beside its truth).

    Raises:
        RecordingError: the path exists already or cannot be written.

    Use as a context manager so that the file is finished (summary and index written)::

        with RecordingWriter("out.mcap") as recording:
            recording.write("/k01/skeletons", SKELETON_GROUP, cdr_bytes, stamp_ns)

    """

    def __init__(
        self,
        path: str | Path,
        *,
        compression: str = "zstd",
        chunk_size: int = 4 << 20,
        level: int = ZSTD_LEVEL,
        discard_on_error: bool = False,
        bag_metadata: bool = False,
    ) -> None:
        self.path = Path(path)
        self.discard_on_error = discard_on_error
        self.folder: Path | None = None
        file_path = self.path
        if self.path.suffix != ".mcap":
            self.folder = self.path
            file_path = self.path / f"{self.path.name}_0.mcap"
        self.metadata_path: Path | None = None
        """Where ``metadata.yaml`` is written (a folder's, or beside a file with bag_metadata)."""
        if self.folder is not None or bag_metadata:
            self.metadata_path = file_path.parent / BAG_METADATA
        for taken in (self.path, self.metadata_path):
            if taken is not None and taken.exists():
                msg = f"{taken} exists already; choose a new recording path"
                raise RecordingError(msg)
        if compression.lower() not in COMPRESSIONS:
            msg = f"unknown MCAP compression {compression!r}: use zstd, lz4 or none"
            raise RecordingError(msg)
        try:
            file_path.parent.mkdir(parents=True, exist_ok=True)
            self._stream: IO[bytes] = file_path.open("xb")
        except OSError as exc:
            msg = f"cannot create recording {file_path}: {exc}"
            raise RecordingError(msg) from exc
        self.file_path = file_path
        self._writer = McapWriter(
            self._stream, chunk_size=chunk_size, compression=compression.lower(), level=level
        )
        self._writer.start(profile="ros2", library="hiros")
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._routes: dict[tuple[str, str], _Route] = {}
        self._initial: list[tuple[str, str, bytes]] = []
        self.counts: Counter[tuple[str, str]] = Counter()
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.closed = False

    def _channel(self, topic: str, msgtype: str) -> int:
        key = (topic, msgtype)
        channel = self._channels.get(key)
        if channel is None:
            schema = self._schemas.get(msgtype)
            if schema is None:
                schema = self._writer.register_schema(
                    name=msgtype,
                    encoding="ros2msg",
                    data=message_definition(msgtype).encode(),
                )
                self._schemas[msgtype] = schema
            metadata = {
                "offered_qos_profiles": yaml.safe_dump(offered_qos(topic), sort_keys=False),
                "topic_type_hash": type_hash(msgtype),
            }
            channel = self._writer.register_channel(
                topic=topic, message_encoding="cdr", schema_id=schema, metadata=metadata
            )
            self._channels[key] = channel
        return channel

    def write(
        self,
        topic: str,
        msgtype: str,
        data: bytes,
        log_time_ns: int,
        publish_time_ns: int | None = None,
    ) -> None:
        """Append one message of CDR bytes; ``log_time_ns`` orders the recording."""
        route = self._route(topic, msgtype)
        log_time_ns = _checked_time(topic, log_time_ns)
        publish = log_time_ns if publish_time_ns is None else _checked_time(topic, publish_time_ns)
        if self._initial:
            self._write_initial(log_time_ns)
        route.sequence += 1
        self._writer.add_message(route.channel, log_time_ns, data, publish, route.sequence)
        self._counted(route, log_time_ns)

    def write_group(self, topic: str, group: object, log_time_ns: int | None = None) -> None:
        """Append a SkeletonGroup (encoded with the codec); log time defaults to its stamp.

        The codec encodes it straight into the open MCAP chunk (``encode_group_into``): no
        intermediate ``bytes``.
        """
        from hiros_core.codec import encode_group_into

        route = self._route(topic, SKELETON_GROUP)
        stamp = group.stamp_ns if log_time_ns is None else log_time_ns  # type: ignore[attr-defined]
        stamp = _checked_time(topic, stamp)
        if self._initial:
            self._write_initial(stamp)
        size = encode_group_into(group, self._space)  # type: ignore[arg-type]
        route.sequence += 1
        self._writer.commit(route.channel, stamp, size, stamp, route.sequence)
        self._counted(route, stamp)

    def write_initial(self, topic: str, msgtype: str, data: bytes) -> None:
        """Append a message that belongs at the start, at the log time of the next one.

        For what describes the whole recording (the calibration a run used): logged at the
        first data message's time, it keeps the file's timeline within the data (at 0, a
        player's timeline would span 54 years). Without any later message it is logged at 0.
        """
        self._route(topic, msgtype)  # a bad type is refused now, not with the next message
        self._initial.append((topic, msgtype, bytes(data)))

    def _write_initial(self, log_time_ns: int) -> None:
        initial, self._initial = self._initial, []
        for topic, msgtype, data in initial:
            self.write(topic, msgtype, data, log_time_ns)

    def _space(self, size: int) -> tuple[np.ndarray, int]:
        at = self._writer.reserve(size)  # may move the chunk to a larger buffer: first
        return self._writer.buffer, at

    def _route(self, topic: str, msgtype: str) -> _Route:
        """The topic's channel, registered (and the type normalised) on its first message."""
        if self.closed:
            msg = f"recording {self.path} is closed; open a new writer"
            raise RecordingError(msg)
        route = self._routes.get((topic, msgtype))
        if route is None:
            normalized = normalize_msgtype(msgtype)
            channel = self._channel(topic, normalized)
            same = [r for r in self._routes.values() if r.channel == channel]
            route = same[0] if same else _Route(channel, (topic, normalized))
            self._routes[(topic, msgtype)] = route
        return route

    def _counted(self, route: _Route, log_time_ns: int) -> None:
        self.counts[route.counted] += 1
        if self.start_ns is None:
            self.start_ns = self.end_ns = log_time_ns
        elif log_time_ns < self.start_ns:
            self.start_ns = log_time_ns
        elif log_time_ns > self.end_ns:  # type: ignore[operator]
            self.end_ns = log_time_ns

    def write_marker_array(self, topic: str, data: object, log_time_ns: int | None = None) -> None:
        """Append a MarkerArrayData; log time defaults to its first marker's stamp (else 0)."""
        from hiros_core.codec import encode_marker_array

        stamps = data.stamps_ns  # type: ignore[attr-defined]
        if log_time_ns is None:
            log_time_ns = int(stamps[0]) if len(stamps) else (self.end_ns or 0)
        self.write(topic, MARKER_ARRAY, encode_marker_array(data), log_time_ns)

    def close(self) -> None:
        """Finish the file (summary, indexes) and write ``metadata.yaml`` where one is kept."""
        if self.closed:
            return
        if self._initial:
            self._write_initial(0)
        self.closed = True
        try:
            self._writer.add_metadata(
                "rosbag2",
                {"serialized_metadata": yaml.safe_dump(self._bag_info(), sort_keys=False),
                 "ROS_DISTRO": "jazzy"},
            )  # fmt: skip
            self._writer.finish()
        except BaseException:
            self._writer.abort()
            raise
        finally:
            self._stream.close()
        if self.metadata_path is not None:
            info = {"rosbag2_bagfile_information": self._bag_info()}
            self.metadata_path.write_text(yaml.safe_dump(info, sort_keys=False))

    def discard(self) -> None:
        """Close and delete the recording: the output of a failed run must not pass for one.

        Only what this writer created goes (its MCAP file, its ``metadata.yaml`` and a folder
        it made once empty).
        """
        with contextlib.suppress(Exception):  # the file goes anyway
            self.close()
        self.file_path.unlink(missing_ok=True)
        if self.metadata_path is not None:
            self.metadata_path.unlink(missing_ok=True)
        if self.folder is not None:
            with contextlib.suppress(OSError):  # not empty: something else was put there
                self.folder.rmdir()

    def _bag_info(self) -> dict[str, object]:
        """rosbag2's bag metadata (version 9) of the one MCAP file: ``metadata.yaml``'s content."""
        start = self.start_ns or 0
        duration = (self.end_ns or 0) - start
        total = sum(self.counts.values())
        return {
            "version": 9,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": total,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": topic,
                        "type": msgtype,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": offered_qos(topic),
                        "type_description_hash": type_hash(msgtype),
                    },
                    "message_count": count,
                }
                for (topic, msgtype), count in self.counts.items()
            ],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.file_path.name],
            "files": [
                {
                    "path": self.file_path.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": total,
                }
            ],
            "custom_data": {},
            "ros_distro": "jazzy",
        }

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if not self.discard_on_error:
            self.close()
        elif exc_type is not None and issubclass(exc_type, Exception):
            self.discard()
        else:
            try:
                self.close()
            except Exception:
                self.discard()
                raise
