"""``hiros run`` over a short simulated recording: outputs, accounting, determinism."""

from __future__ import annotations

import gc
import itertools
from collections.abc import Callable
from pathlib import Path

import pytest

from hiros_core.calibration import Calibration, load_calibration
from hiros_core.errors import ConfigError, RecordingError
from hiros_core.model import SkeletonGroup
from hiros_core.recording import RecordingReader
from hiros_pipeline import STAGES, PipelineParams, run_recording
from hiros_tracker import Tracker


@pytest.fixture(scope="module")
def short_recording(simulated_scene: Callable[..., Path]) -> Path:
    return simulated_scene("sim", n_cameras=2, n_people=2, duration=8.0, seed=3)


def test_every_stage_writes_and_every_frame_is_accounted_for(
    short_recording: Path, tmp_path: Path
) -> None:
    calibration = load_calibration(short_recording / "calibration.yaml")
    out = tmp_path / "out.mcap"
    summary = run_recording(short_recording / "recording.mcap", calibration, out, PipelineParams())
    with RecordingReader(short_recording / "recording.mcap") as reader:
        camera_messages = sum(1 for _ in reader.messages())
    bridge_dropped = sum(v for k, v in summary.dropped.items() if k.startswith("reader"))
    assert sum(summary.frames_in.values()) + bridge_dropped == camera_messages
    assert summary.frames_total == summary.processed + sum(summary.dropped.values())
    with RecordingReader(out) as reader:
        topics = set(reader.topics)
    assert {f"/hiros/{stage}" for stage in STAGES} <= topics
    assert {"/hiros/filter/markers", "/hiros/calibration", "/tf_static"} <= topics
    for stage in STAGES:
        assert summary.published[stage] > 0
    assert 1 <= len(summary.people["merger"]) <= 4


def test_runs_are_deterministic_in_one_process_or_two(
    short_recording: Path, tmp_path: Path
) -> None:
    calibration = load_calibration(short_recording / "calibration.yaml")
    runs = {
        name: run_recording(short_recording / "recording.mcap", calibration,
                            tmp_path / f"{name}.mcap", processes=processes)
        for name, processes in (("one", 1), ("again", 1), ("two", 2))
    }  # fmt: skip
    messages = {}
    for name in runs:
        with RecordingReader(tmp_path / f"{name}.mcap") as reader:
            messages[name] = [(m.topic, m.log_time_ns, m.data) for m in reader.messages()]
    assert messages["one"] == messages["again"] == messages["two"]
    assert runs["one"].dropped == runs["two"].dropped
    assert runs["one"].dropped_detections == runs["two"].dropped_detections
    assert runs["one"].processed == runs["two"].processed
    assert runs["one"].frames_in == runs["two"].frames_in
    assert runs["one"].published == runs["two"].published
    assert "waiting" in runs["two"].seconds
    # CPU over the run's own span: the calling thread cannot use more than the wall time
    assert set(runs["one"].cpu) == {"main", "writer"}
    assert set(runs["two"].cpu) == {"main", "writer", "child"}
    assert 0 < runs["one"].cpu["main"] <= runs["one"].wall_time * 1.05 + 0.01
    assert runs["two"].cpu["child"] > 0


def test_only_the_outputs_asked_for_are_written_and_all_are_counted(
    short_recording: Path, tmp_path: Path
) -> None:
    calibration = load_calibration(short_recording / "calibration.yaml")
    recording = short_recording / "recording.mcap"
    whole = run_recording(recording, calibration, tmp_path / "all.mcap", processes=1)
    part = run_recording(
        recording, calibration, tmp_path / "filter.mcap", processes=1, write=("filter", "markers")
    )
    read = {}
    for name in ("all", "filter"):
        with RecordingReader(tmp_path / f"{name}.mcap") as reader:
            read[name] = [(m.topic, m.log_time_ns, m.data) for m in reader.messages()]
    kept = {"/hiros/calibration", "/tf_static", "/hiros/filter", "/hiros/filter/markers"}
    assert {topic for topic, _, _ in read["filter"]} == kept
    assert read["filter"] == [m for m in read["all"] if m[0] in kept]
    assert part.published == whole.published
    assert part.duration == whole.duration
    with pytest.raises(ConfigError, match="cannot write skeletons"):
        run_recording(recording, calibration, tmp_path / "x.mcap", write=("skeletons",))
    assert not (tmp_path / "x.mcap").exists()


def test_an_unreadable_recording_raises_from_the_reading_process(tmp_path: Path) -> None:
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(b"not a recording at all")
    with pytest.raises(RecordingError):
        run_recording(broken, Calibration("k01"), tmp_path / "out.mcap", processes=2)


def test_an_error_in_the_reading_process_mid_run_is_raised_here(
    short_recording: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The 30th frame is in the 4th batch: it comes through another pipe than the first.
    frames = itertools.count()
    track = Tracker.update

    def failing_update(tracker: Tracker, group: SkeletonGroup) -> SkeletonGroup:
        if next(frames) == 30:
            raise ValueError("the tracker failed on frame 30")
        return track(tracker, group)

    monkeypatch.setattr(Tracker, "update", failing_update)  # before the fork: the child's too
    calibration = load_calibration(short_recording / "calibration.yaml")
    out = tmp_path / "out.mcap"
    with pytest.raises(ValueError, match="frame 30"):
        run_recording(short_recording / "recording.mcap", calibration, out, processes=2)
    assert not out.exists()


def test_the_objects_frozen_for_the_run_are_handed_back(
    short_recording: Path, tmp_path: Path
) -> None:
    calibration = load_calibration(short_recording / "calibration.yaml")
    recording = short_recording / "recording.mcap"
    gc.unfreeze()
    run_recording(recording, calibration, tmp_path / "a.mcap", processes=2)
    assert gc.get_freeze_count() == 0
    gc.freeze()  # a caller's own frozen objects stay frozen
    try:
        run_recording(recording, calibration, tmp_path / "b.mcap", processes=1)
        assert gc.get_freeze_count() > 0  # (fewer: frozen objects that died are freed)
    finally:
        gc.unfreeze()


def test_a_damaged_chunk_is_accounted_for_and_described(
    short_recording: Path, tmp_path: Path
) -> None:
    data = bytearray((short_recording / "recording.mcap").read_bytes())
    data[len(data) // 4] ^= 0xFF  # inside the first chunk's compressed records
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    calibration = load_calibration(short_recording / "calibration.yaml")
    summary = run_recording(damaged, calibration, tmp_path / "out.mcap", processes=1)
    with RecordingReader(short_recording / "recording.mcap") as reader:
        camera_messages = sum(1 for _ in reader.messages())
    reader_dropped = sum(v for k, v in summary.dropped.items() if k.startswith("reader"))
    assert summary.dropped["reader: damaged_chunk"] > 0
    assert sum(summary.frames_in.values()) + reader_dropped == camera_messages
    assert summary.frames_total == summary.processed + sum(summary.dropped.values())
    assert "damaged" in summary.problems[0]


@pytest.mark.parametrize("processes", [1, 2])
def test_a_failed_run_leaves_no_output_behind(tmp_path: Path, processes: int) -> None:
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(b"not a recording at all")
    for out in (tmp_path / "out.mcap", tmp_path / "folder"):
        with pytest.raises(RecordingError):
            run_recording(broken, Calibration("k01"), out, processes=processes)
        assert not out.exists()  # a second try is not told the output "exists already"
