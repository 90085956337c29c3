"""hiros_core.recording: read and write recordings (rosbag2 MCAP/sqlite3, ROS 1 bags) as CDR."""

from hiros_core.recording.groups import (
    group_topics,
    iter_groups,
    iter_logged_groups,
    read_camera_groups,
    require_camera_topics,
    source_name,
)
from hiros_core.recording.msgdefs import message_definition
from hiros_core.recording.reader import MessageBatch, RecordedMessage, RecordingReader
from hiros_core.recording.writer import MARKER_ARRAY, SKELETON_GROUP, RecordingWriter

__all__ = [
    "MARKER_ARRAY",
    "SKELETON_GROUP",
    "MessageBatch",
    "RecordedMessage",
    "RecordingReader",
    "RecordingWriter",
    "group_topics",
    "iter_groups",
    "iter_logged_groups",
    "message_definition",
    "read_camera_groups",
    "require_camera_topics",
    "source_name",
]
