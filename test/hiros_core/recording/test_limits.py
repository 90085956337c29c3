"""Issue 21 cases 8 and 9: sizes written in a file are checked before anything is allocated."""

from __future__ import annotations

import io
import resource
import struct
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import zstandard
from mcap.reader import make_reader

from hiros_core.codec import decode_group, decode_marker_array, encode_group
from hiros_core.driver import group_to_driver_markers
from hiros_core.errors import CodecError
from hiros_core.layouts import AZURE_KINECT
from hiros_core.limits import MAX_BODIES, MAX_CHUNK_BYTES, MAX_MARKERS
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_core.recording import RecordingWriter, iter_groups

T0 = 1_700_000_000_000_000_000
_UNCOMPRESSED_SIZE_AT = 1 + 8 + 8 + 8  # chunk record: opcode, length, start and end times


def _max_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _group(bodies: int, stamp_ns: int) -> SkeletonGroup:
    skeletons = []
    for k in range(bodies):
        skeleton = Skeleton.empty(AZURE_KINECT, skeleton_id=k, src_time_ns=stamp_ns,
                                  src_frame="k01_depth_camera_link")  # fmt: skip
        skeleton.marker_present[:] = True
        skeleton.positions[:] = [0.1 * k, 0.0, 2.0]
        skeletons.append(skeleton)
    return SkeletonGroup(stamp_ns, "k01_depth_camera_link", skeletons)


def _recording(path: Path, frames: int = 40, bodies: dict[int, int] | None = None) -> Path:
    """SkeletonGroups of one body on /k01/skeletons, ``bodies[frame]`` bodies in some."""
    with RecordingWriter(path, chunk_size=16_000) as writer:  # several chunks
        for k in range(frames):
            stamp = T0 + k * 33_000_000
            writer.write_group("/k01/skeletons", _group((bodies or {}).get(k, 1), stamp))
    return path


def _second_chunk(path: Path) -> int:
    """Where the second chunk starts (the first one defines the channel)."""
    with path.open("rb") as stream:
        chunks = make_reader(stream).get_summary().chunk_indexes
    assert len(chunks) > 2
    return sorted(c.chunk_start_offset for c in chunks)[1]


@pytest.mark.parametrize("claimed", [16 << 30, 1 << 40])
def test_case8_a_chunk_claiming_gigabytes_is_skipped_not_allocated(
    tmp_path: Path, claimed: int
) -> None:
    path = _recording(tmp_path / "rec.mcap")
    data = bytearray(path.read_bytes())
    start = _second_chunk(path)
    struct.pack_into("<Q", data, start + _UNCOMPRESSED_SIZE_AT, claimed)
    before = _max_rss_mb()
    for name, content in {"indexed.mcap": data, "cut.mcap": data[: len(data) // 2]}.items():
        (tmp_path / name).write_bytes(content)
        drops: Counter[str] = Counter()
        problems: list[str] = []
        groups = list(iter_groups(tmp_path / name, drops=drops, problems=problems))
        assert 0 < len(groups) < 40
        assert drops["oversized_chunk"] >= 1
        assert any("would decompress to" in p for p in problems)
    assert _max_rss_mb() - before < 200


def _mcap_with_chunk(path: Path, payload: int, claimed: int) -> Path:
    """A summary-less MCAP whose one zstd chunk holds a message of ``payload`` zero bytes
    and says it decompresses to ``claimed`` bytes (compressed: a few tens of KB)."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Schema

    message_head = struct.pack("<BQHIQQ", 0x05, 2 + 4 + 8 + 8 + payload, 1, 1, T0, T0)
    compressor = zstandard.ZstdCompressor().compressobj()
    compressed = io.BytesIO()
    compressed.write(compressor.compress(message_head))
    zeros = bytes(16 << 20)
    for _ in range(payload // len(zeros)):
        compressed.write(compressor.compress(zeros))
    compressed.write(compressor.compress(bytes(payload % len(zeros))))
    compressed.write(compressor.flush())
    builder = RecordBuilder()
    Header(profile="ros2", library="test").write(builder)
    Schema(id=1, name="hiros_skeleton_msgs/msg/SkeletonGroup", encoding="ros2msg",
           data=b"").write(builder)  # fmt: skip
    Channel(id=1, schema_id=1, topic="/k01/skeletons", message_encoding="cdr",
            metadata={}).write(builder)  # fmt: skip
    chunk = Chunk(compression="zstd", data=compressed.getvalue(), message_start_time=T0,
                  message_end_time=T0, uncompressed_crc=0, uncompressed_size=claimed)  # fmt: skip
    chunk.write(builder)
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    path.write_bytes(b"\x89MCAP0\r\n" + bytes(builder.end()) + b"\x89MCAP0\r\n")
    return path


@pytest.mark.parametrize(("payload", "claimed"), [(1 << 30, (1 << 30) + 30), (1 << 30, 4096)])
def test_case8_a_small_zstd_chunk_inflating_to_a_gigabyte_is_not_inflated(
    tmp_path: Path, payload: int, claimed: int
) -> None:
    path = _mcap_with_chunk(tmp_path / "bomb.mcap", payload, claimed)
    assert path.stat().st_size < 100_000
    before = _max_rss_mb()
    drops: Counter[str] = Counter()
    assert list(iter_groups(path, drops=drops)) == []
    reason = "oversized_chunk" if claimed > MAX_CHUNK_BYTES else "damaged_chunk"
    assert drops[reason] == 1
    assert _max_rss_mb() - before < 200


def test_case9_frames_of_too_many_bodies_are_dropped_and_counted(tmp_path: Path) -> None:
    crowded = dict.fromkeys(range(0, 40, 20), 1000)
    path = _recording(tmp_path / "crowd.mcap", bodies=crowded)
    drops: Counter[str] = Counter()
    groups = [group for _, group in iter_groups(path, drops=drops)]
    assert len(groups) == 40 - len(crowded)
    assert drops["too_many_bodies"] == len(crowded)
    with pytest.raises(CodecError, match=f"at most {MAX_BODIES}"):
        decode_group(encode_group(_group(MAX_BODIES + 1, T0)))
    assert len(decode_group(encode_group(_group(MAX_BODIES, T0))).skeletons) == MAX_BODIES


def test_case9_a_driver_message_of_too_many_markers_is_dropped_and_counted(
    tmp_path: Path,
) -> None:
    path = tmp_path / "markers.mcap"
    huge = group_to_driver_markers(_group(1250, T0))  # 40 000 markers
    assert len(huge.actions) > MAX_MARKERS
    with RecordingWriter(path) as writer:
        for k in range(10):
            stamp = T0 + k * 33_000_000
            data = huge if k == 5 else group_to_driver_markers(_group(2, stamp))
            writer.write_marker_array("/k01/body_tracking_data", data, stamp)
    drops: Counter[str] = Counter()
    groups = [group for _, group in iter_groups(path, drops=drops)]
    assert len(groups) == 9
    assert drops["too_many_markers"] == 1
    from hiros_core.codec import encode_marker_array

    with pytest.raises(CodecError, match=f"at most {MAX_MARKERS}"):
        decode_marker_array(encode_marker_array(huge))


def test_bodies_past_the_limit_from_a_driver_message_are_dropped() -> None:
    from hiros_core.codec import encode_marker_array
    from hiros_core.driver import DriverBridge

    bridge = DriverBridge()
    crowd = group_to_driver_markers(_group(MAX_BODIES + 1, T0))
    assert len(crowd.actions) <= MAX_MARKERS
    assert bridge.update_bytes(encode_marker_array(crowd)) is None
    assert bridge.drops["too_many_bodies"] == 1
    assert np.isfinite(bridge.update_bytes(
        encode_marker_array(group_to_driver_markers(_group(3, T0 + 1)))
    ).skeletons[0].positions).any()  # fmt: skip


@pytest.mark.parametrize("length", [2**40, 2**63 - 1])
def test_a_record_length_past_the_file_is_a_cut_file_not_a_memory_error(
    tmp_path: Path, length: int
) -> None:
    """Found by fuzzing: the buffered reader allocated a record's stated length at once."""
    path = _recording(tmp_path / "rec.mcap")
    data = bytearray(path.read_bytes())
    start = _second_chunk(path)
    name_at = start + _UNCOMPRESSED_SIZE_AT + 8 + 4  # then the uncompressed CRC
    (name_length,) = struct.unpack_from("<I", data, name_at)
    struct.pack_into("<Q", data, name_at + 4 + name_length, length)  # the records' length
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 3 // 4])  # no summary: read straight through
    before = _max_rss_mb()
    drops: Counter[str] = Counter()
    problems: list[str] = []
    groups = list(iter_groups(cut, drops=drops, problems=problems))
    assert 0 < len(groups) < 40
    assert any("ends early or is damaged" in p for p in problems)
    assert _max_rss_mb() - before < 200


@pytest.mark.parametrize("compression", ["lz4", "bz2"])
def test_a_ros1_bag_chunk_past_the_limit_is_not_inflated(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, compression: str
) -> None:
    from rosbags.rosbag1 import Writer as Rosbag1Writer
    from rosbags.typesys import Stores, get_typestore

    from hiros_core.errors import RecordingError
    from hiros_core.recording import RecordingReader, rosbags_source

    store = get_typestore(Stores.ROS1_NOETIC)
    bag = tmp_path / "take.bag"
    writer = Rosbag1Writer(bag)
    writer.set_compression(getattr(Rosbag1Writer.CompressionFormat, compression.upper()))
    with writer:
        connection = writer.add_connection("/note", "std_msgs/msg/String", typestore=store)
        note = store.types["std_msgs/msg/String"](data="0" * (3 << 20))  # 3 MB, compresses well
        writer.write(connection, 10**9, store.serialize_ros1(note, "std_msgs/msg/String"))
    assert bag.stat().st_size < 1 << 20
    with RecordingReader(bag) as recording:
        assert len(next(iter(recording)).data) > 3 << 20  # read whole within the limit
    monkeypatch.setattr(rosbags_source, "MAX_CHUNK_BYTES", 1 << 20)
    with RecordingReader(bag) as recording, pytest.raises(RecordingError, match="more than the"):
        list(recording)
