"""Issue 21: property-based fuzzing of every reader and of the live input decoding.

Each reader is given damaged or hostile input built by hypothesis from a valid one (bytes
flipped, cut, length and count fields overwritten with huge values) or from scratch. It must
give a result or raise its own error type, a ``HirosError`` (never a traceback of another
kind), and the process's peak memory must stay within what the limits allow
(``hiros_core.limits``, ``hiros_core.safe_yaml``). ``--hypothesis-show-statistics`` prints
how many examples each target ran.
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import struct
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hiros_convert import read_streams
from hiros_core.codec import decode_group, decode_marker_fields, encode_group
from hiros_core.driver import DriverBridge, group_to_driver_markers
from hiros_core.errors import CodecError, ConfigError, HirosError
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_core.recording import RecordingWriter, iter_groups
from hiros_core.safe_yaml import parse_yaml

T0 = 1_700_000_000_000_000_000
MEMORY_BUDGET_MB = 600
"""Peak RSS growth allowed over a whole test: a few chunks at the 128 MiB limit at most."""
FUZZ = settings(
    max_examples=int(os.environ.get("HIROS_FUZZ_EXAMPLES", "150")),  # more: a longer campaign
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


def _max_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


@pytest.fixture
def memory() -> object:
    """Fails the test when the process's peak RSS grew by more than the budget."""
    before = _max_rss_mb()
    yield
    assert _max_rss_mb() - before < MEMORY_BUDGET_MB


def _group(bodies: int, stamp_ns: int) -> SkeletonGroup:
    skeletons = []
    for k in range(bodies):
        skeleton = Skeleton.empty(AZURE_KINECT, skeleton_id=k, src_time_ns=stamp_ns,
                                  src_frame="k01_depth_camera_link")  # fmt: skip
        skeleton.marker_present[:] = True
        skeleton.positions[:] = [0.1 * k, 0.0, 2.0]
        skeletons.append(skeleton)
    return SkeletonGroup(stamp_ns, "k01_depth_camera_link", skeletons)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """Small valid MCAPs: SkeletonGroups and driver MarkerArrays, zstd, lz4 and plain."""
    folder = tmp_path_factory.mktemp("fuzz")
    out = {}
    for compression in ("zstd", "lz4", "none"):
        path = folder / f"{compression}.mcap"
        with RecordingWriter(path, compression=compression, chunk_size=6000) as writer:
            for k in range(12):
                stamp = T0 + k * 33_000_000
                writer.write_group("/k01/skeletons", _group(1 + k % 2, stamp))
                markers = group_to_driver_markers(_group(1, stamp))
                writer.write_marker_array("/k02/body_tracking_data", markers, stamp)
        out[compression] = path.read_bytes()
    return out


edits = st.lists(
    st.tuples(
        st.sampled_from(["flip", "u64", "u32", "cut"]),
        st.floats(0, 1),  # where, as a fraction of the length
        st.sampled_from([1, 0x80, 0xFF, 2**31, 2**32 - 1, 40_000, 2**34, 2**40, 2**63 - 1]),
    ),
    min_size=1,
    max_size=4,
)
"""Edits to a valid input: a byte flipped, a u32 or u64 field set (huge), or the end cut."""


def damaged(original: bytes, changes: list[tuple[str, float, int]]) -> bytes:
    """``original`` with ``changes`` (see ``edits``) applied in order."""
    data = bytearray(original)
    for kind, where, value in changes:
        if len(data) < 16:
            break
        at = min(int(where * len(data)), len(data) - 8)
        if kind == "flip":
            data[at] ^= value & 0xFF or 1
        elif kind == "u64":
            struct.pack_into("<Q", data, at, value)
        elif kind == "u32":
            struct.pack_into("<I", data, at, value & 0xFFFFFFFF)
        else:
            del data[max(at, 8) :]
    return bytes(data)


@FUZZ
@given(compression=st.sampled_from(["zstd", "lz4", "none"]), changes=edits)
def test_fuzz_mcap_reader_gives_groups_or_a_recording_error(
    recordings: dict[str, bytes],
    tmp_path: Path,
    memory: object,
    compression: str,
    changes: list[tuple[str, float, int]],
) -> None:
    content = damaged(recordings[compression], changes)
    path = tmp_path / "fuzzed.mcap"
    path.write_bytes(content)
    drops: Counter[str] = Counter()
    problems: list[str] = []
    try:
        groups = list(iter_groups(path, drops=drops, problems=problems))
    except HirosError:
        groups = []
    assert len(groups) <= 24


@FUZZ
@given(
    kind=st.sampled_from(["SkeletonGroup", "MarkerArray"]),
    bodies=st.integers(0, 3),
    changes=st.one_of(edits, st.none()),
    noise=st.binary(max_size=400),
)
def test_fuzz_live_decoding_raises_only_codec_errors(
    memory: object, kind: str, bodies: int, changes: list | None, noise: bytes
) -> None:
    """The bytes a node receives: SkeletonGroup and driver MarkerArray, damaged or random."""
    from hiros_core.codec import encode_marker_array

    group = _group(bodies, T0)
    source = (
        encode_group(group) if kind == "SkeletonGroup"
        else encode_marker_array(group_to_driver_markers(group))
    )  # fmt: skip
    payload = noise if changes is None else damaged(source, changes)
    for decode in (decode_group, decode_marker_fields):
        with contextlib.suppress(CodecError):
            decode(payload)
    bridge = DriverBridge()
    bridge.update_batch(payload, np.array([0]), np.array([len(payload)]))
    bridge._update_counted(payload)
    assert bridge.accounted == 2


yaml_text = st.one_of(
    st.text(max_size=300),
    st.recursive(
        st.one_of(st.integers(), st.floats(), st.text(max_size=8), st.none()),
        lambda inner: st.one_of(st.lists(inner, max_size=4),
                                st.dictionaries(st.text(max_size=5), inner, max_size=4)),
        max_leaves=40,
    ).map(json.dumps),  # JSON is YAML
    st.builds(lambda depth, width: "".join(
        f"a{i}: &a{i} [{', '.join([f'*a{i - 1}' if i else 'x'] * width)}]\n" for i in range(depth)
    ), st.integers(1, 12), st.integers(1, 12)),  # alias towers, bombs among them
    st.integers(1, 3000).map(lambda n: "[" * n + "]" * n),
)  # fmt: skip


@FUZZ
@given(text=yaml_text)
def test_fuzz_yaml_gives_data_or_a_config_error(memory: object, text: str) -> None:
    with contextlib.suppress(ConfigError):
        parse_yaml(text, source="fuzzed", error=ConfigError)


cell = st.one_of(
    st.sampled_from(["", "NA", "nan", "inf", "-inf", "1e400", "1e30", "-5", "Pelvis", "k-1"]),
    st.integers(-(2**70), 2**70).map(str),
    st.floats().map(str),
    st.text(max_size=6).filter(lambda s: "," not in s and "\n" not in s and "\r" not in s),
)


@FUZZ
@given(rows=st.lists(st.lists(cell, min_size=7, max_size=7), max_size=30))
def test_fuzz_generic_csv_counts_or_refuses(tmp_path: Path, memory: object, rows: list) -> None:
    path = tmp_path / "fuzzed.csv"
    lines = ["camera,stamp_ns,body_id,joint,x,y,z", *(",".join(row) for row in rows)]
    path.write_text("\n".join(lines) + "\n")
    with contextlib.suppress(HirosError):
        read_streams(path, "csv", drops=Counter())


json_number = st.one_of(
    st.integers(-(2**70), 2**70).map(str),
    st.sampled_from(["1e400", "-1e400", "1e30", "0.5", "-1", "null", '"x"', "[]", "{}"]),
)


@FUZZ
@given(stamps=st.lists(st.tuples(json_number, json_number), min_size=1, max_size=8))
def test_fuzz_k4abt_json_counts_or_refuses(
    tmp_path: Path, memory: object, stamps: list[tuple[str, str]]
) -> None:
    body = {"body_id": "ID", "joint_positions": [[0.0, 0.0, 2000.0]] * 32,
            "joint_orientations": [[1.0, 0.0, 0.0, 0.0]] * 32}  # fmt: skip
    template = json.dumps({"timestamp_usec": "STAMP", "bodies": [body]})
    frames = [template.replace('"STAMP"', s).replace('"ID"', b) for s, b in stamps]
    path = tmp_path / "fuzzed.json"
    path.write_text('{"frames": [' + ", ".join(frames) + "]}")
    with contextlib.suppress(HirosError):
        read_streams(path, "k4abt-json", drops=Counter())
